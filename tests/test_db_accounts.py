"""Who may do what: accounts with hashed secrets, a patient account kept to its own games, the audit record."""

from __future__ import annotations

import json
import random
from dataclasses import replace

import pytest

from game.cli import main
from game.db import Database
from game.db.accounts import AccessDenied, Account, audit_rows, authenticate, hash_secret, verify_secret
from game.db.pending import keep_pending
from game.play import PlayOptions, check_account
from pg_station import make_record


@pytest.fixture
def clinic(tmp_path, monkeypatch):
    """A database with two patients, a therapist (PIN 4711) and a patient account for P001 (PIN 1234)."""
    monkeypatch.delenv("REHAB_USER", raising=False)
    monkeypatch.delenv("REHAB_PIN", raising=False)
    path = tmp_path / "clinic.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
        db.add_patient("P002")
    monkeypatch.setenv("REHAB_NEW_PIN", "4711")
    assert main(["accounts", "--add", "anna", "--db", str(path)]) == 0   # the first therapist: no sign-in yet
    monkeypatch.setenv("REHAB_USER", "anna")
    monkeypatch.setenv("REHAB_PIN", "4711")
    monkeypatch.setenv("REHAB_NEW_PIN", "1234")
    assert main(["accounts", "--add", "p1", "--role", "patient", "--patient", "P001", "--db", str(path)]) == 0
    monkeypatch.delenv("REHAB_NEW_PIN")
    return path


def test_secrets_are_stored_only_as_salted_scrypt_hashes(clinic):
    a, b = hash_secret("4711"), hash_secret("4711")
    assert a != b and a.startswith("scrypt$") and verify_secret("4711", a) and not verify_secret("4712", a)
    assert not verify_secret("4711", "plain") and not verify_secret("4711", "scrypt$x$y$z$00$00")
    raw = clinic.read_bytes()
    assert b"4711" not in raw and b"1234" not in raw
    with Database(clinic) as db:
        assert authenticate(db, "anna", "4711") == Account("anna", "therapist", None)
        with pytest.raises(AccessDenied, match="wrong account name or password"):
            authenticate(db, "anna", "0000")


def test_with_accounts_the_therapist_commands_need_a_therapist(clinic, monkeypatch, capsys):
    assert main(["patients", "--db", str(clinic)]) == 0
    monkeypatch.delenv("REHAB_USER")
    assert main(["patients", "--db", str(clinic)]) == 1
    assert "has accounts: give --user NAME" in capsys.readouterr().err
    monkeypatch.setenv("REHAB_PIN", "0000")
    assert main(["patients", "--db", str(clinic), "--user", "anna"]) == 1
    err = capsys.readouterr().err
    assert "wrong account name or password/PIN" in err and err.count("\n") == 1


def test_a_patient_account_cannot_open_another_patients_data_or_the_therapists_screens(clinic, monkeypatch, capsys,
                                                                                         tmp_path):
    monkeypatch.setenv("REHAB_USER", "p1")
    monkeypatch.setenv("REHAB_PIN", "1234")
    for argv in (["report", "P002", "--out", str(tmp_path / "r.html")],
                 ["report", "P001", "--out", str(tmp_path / "r.html")],
                 ["export", "--out", str(tmp_path / "csv"), "--patient", "P002"],
                 ["export", "--out", str(tmp_path / "csv")],
                 ["patients"], ["accounts"], ["accounts", "--audit"], ["backup", "--out", str(tmp_path / "b.sqlite3")],
                 ["rom-test", "--patient", "P001", "--test", "shoulder_flexion"],
                 ["accounts", "--add", "p3", "--role", "patient", "--patient", "P002"]):
        assert main([*argv, "--db", str(clinic)]) == 1, argv
        assert "account p1 (patient) may not" in capsys.readouterr().err, argv
    assert not (tmp_path / "r.html").exists() and not (tmp_path / "csv").exists()
    opts = PlayOptions(db_path=clinic, user="p1", patient="P001")
    assert check_account(replace(opts, scene="game")) == Account("p1", "patient", "P001")   # own games: yes
    for scene, patient in (("game", "P002"), ("progress", "P001"), ("rom", "P001"), ("home", None), ("live", None),
                           ("calibrate", None), ("progress", "P002")):
        with pytest.raises(AccessDenied, match="may not"):
            check_account(replace(opts, scene=scene, patient=patient))
    assert main(["play", "--headless", "--db", str(clinic), "--scene", "progress", "--patient", "P002"]) == 1
    assert "account p1 (patient) may not progress for patient P002" in capsys.readouterr().err
    monkeypatch.setenv("REHAB_USER", "anna")
    monkeypatch.setenv("REHAB_PIN", "4711")
    assert check_account(replace(opts, user=None, scene="progress", patient="P002")).role == "therapist"


def test_accepting_changing_and_exporting_are_audited_once(clinic, tmp_path, capsys):
    rec = replace(make_record("P001", 0, random.Random(3), None), accepted_by="anna")
    with Database(clinic) as db:
        db.store_result(rec)
        db.store_result(rec)   # sent again: one result, one audit row
    keep_pending(clinic, replace(make_record("P001", 2, random.Random(4), None), accepted_by="anna"))
    old = replace(make_record("P001", 4, random.Random(5), None))
    path = keep_pending(clinic, old)   # a pending file written before accounts existed has no accepted_by
    data = json.loads(path.read_text())
    del data["accepted_by"]
    path.write_text(json.dumps(data))
    assert main(["patients", "--add", "P003", "--db", str(clinic)]) == 0
    assert main(["export", "--out", str(tmp_path / "csv"), "--patient", "P001", "--db", str(clinic)]) == 0
    with Database(clinic) as db:   # this open stores the two pending results
        assert db.store_pending_results() == 0
        rows = audit_rows(db)
        assert len(db.rom_results("P001")) == 3
    accepts = [r for r in rows if r.action == "accept"]
    assert len(accepts) == 2 and {r.account for r in accepts} == {"anna"} and rec.uid in accepts[0].what
    assert [(r.account, r.action, r.patient_id) for r in rows if r.action != "accept"] == [
        ("anna", "change", None), ("anna", "change", "P001"), ("anna", "change", "P003"), ("anna", "export", "P001")]
    assert main(["accounts", "--audit", "--patient", "P001", "--db", str(clinic)]) == 0
    assert "export   P001" in capsys.readouterr().out


def test_without_accounts_everything_works_as_before(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("REHAB_USER", raising=False)
    path = tmp_path / "solo.sqlite3"
    assert main(["patients", "--add", "P001", "--db", str(path)]) == 0
    assert main(["accounts", "--db", str(path)]) == 0
    assert "no accounts" in capsys.readouterr().out
    assert check_account(PlayOptions(db_path=path, scene="home")) is None
    with Database(path) as db:
        assert [(r.account, r.action) for r in audit_rows(db)] == [("-", "change")]


def test_the_rom_scene_audits_the_signed_in_therapist_with_each_accepted_result(clinic):
    from types import SimpleNamespace

    from game.scenes.rom_test import RomVisit

    visit = RomVisit(clinic, "P001", accepted_by="anna")
    r = SimpleNamespace(test="shoulder_flexion", side="right", angle="right_shoulder_flexion", mode="active",
                        position="seated_arm_at_side", standard="jarm", reference_deg=180.0, max_deg=150.0,
                        start_deg=-5.0, range_deg=155.0, started_s=0.0, ended_s=4.0, compensations=(),
                        estimated_markers=())
    uid = visit.store(r)
    with Database(clinic) as db:
        rows = [a for a in audit_rows(db, "P001") if a.action == "accept"]
    assert [(a.account, uid in a.what) for a in rows] == [("anna", True)]


def test_a_change_of_a_games_limits_on_the_menu_is_audited_with_the_therapist_and_the_values(clinic):
    """Issue 28: who changed a patient's game limits, when and to what, is in the audit record."""
    from game.input import Action, Press
    from game.scenes.game_menu import ChooseGameScene

    class FakeApp:
        def push(self, scene):
            pass

    menu = ChooseGameScene("P001", lambda spec, pid, **kw: None, db_path=clinic, account="anna")
    menu.app = FakeApp()
    menu.handle(Press(Action.SELECT, True))     # the first game's column
    menu.handle(Press(Action.DOWN, True))       # Play -> the first limit (the lowest level)
    menu.handle(Press(Action.RIGHT, True))      # one step up
    with Database(clinic) as db:
        rows = [r for r in audit_rows(db, "P001") if r.action == "limits"]
    assert len(rows) == 1 and rows[0].account == "anna" and rows[0].patient_id == "P001"
    game = menu.games[0]
    level = 1 + round(menu.limits[game.name].min_level * 9)
    assert rows[0].what == f"{game.name}: Lowest level: level {level}"

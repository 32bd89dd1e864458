"""The clinic commands: patients, rom-test (headless, simulated), export/import, backup, report, errors."""

from __future__ import annotations

import sqlite3


from game.cli import main
from game.db import Database


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_patients_add_and_list(tmp_path, capsys):
    db = tmp_path / "r.sqlite3"
    assert run(capsys, "patients", "--db", db)[1].startswith("no patients")
    assert run(capsys, "patients", "--add", "P001", "--db", db)[0] == 0
    code, out, _ = run(capsys, "patients", "--db", db)
    assert code == 0 and "P001" in out
    code, _, err = run(capsys, "patients", "--add", "Jane Doe", "--db", db)
    assert code == 1 and err.count("\n") == 1 and "pseudonym" in err


def test_rom_test_list_and_input_errors_are_one_line(tmp_path, capsys):
    code, out, _ = run(capsys, "rom-test", "--list")
    assert code == 0 and "shoulder_internal_rotation" in out and "AAOS 70 (" in out
    db = tmp_path / "r.sqlite3"
    for argv, message in [
        (("rom-test", "--patient", "P404", "--test", "elbow_flexion", "--db", db), "no patient 'P404'"),
        (("rom-test", "--patient", "P001", "--test", "knee_flexion", "--dry-run"), "unknown rom_test 'knee_flexion'"),
        (("rom-test", "--test", "elbow_flexion"), "give --patient ID"),
        (("rom-test", "--test", "shoulder_extension", "--side", "left", "--dry-run"), "no simulated motion for the left"),
    ]:
        code, _, err = run(capsys, *argv)
        assert code == 1 and message in err and err.count("\n") == 1, (argv, err)


def test_a_damaged_database_is_one_line_for_every_command(tmp_path, capsys):
    bad = tmp_path / "bad.sqlite3"
    bad.write_bytes(b"\x00garbage" * 500)
    before = bad.read_bytes()
    for argv in (("patients",), ("export", "--out", tmp_path / "x"), ("backup",), ("report", "P001", "--out", tmp_path / "r.html"),
                 ("rom-test", "--patient", "P001", "--test", "elbow_flexion")):
        code, _, err = run(capsys, *argv, "--db", bad)
        assert code == 1 and "is not a rehab database or is damaged" in err and err.count("\n") == 1, argv
    assert bad.read_bytes() == before


def test_export_import_backup_report(tmp_path, capsys):
    db = tmp_path / "a.sqlite3"
    with Database(db) as d:
        d.add_patient("P001")
        s = d.start_session("P001", "exercise")
        d.add_exercise_result(s, "reach", 12, 95.0)
    code, out, _ = run(capsys, "export", "--out", tmp_path / "csv", "--db", db)
    assert code == 0 and "1 exercise_results" in out
    code, out, _ = run(capsys, "import", tmp_path / "csv", "--db", tmp_path / "b.sqlite3")
    assert code == 0 and "1 patients" in out and "1 exercise_results" in out
    code, out, _ = run(capsys, "backup", "--out", tmp_path / "b1.sqlite3", "--db", db)
    assert code == 0 and (tmp_path / "b1.sqlite3").is_file()
    code, _, err = run(capsys, "backup", "--out", tmp_path / "b1.sqlite3", "--db", db)
    assert code == 1 and "exists" in err
    code, out, _ = run(capsys, "report", "P001", "--out", tmp_path / "rep" / "report.html", "--db", db)
    assert code == 0 and (tmp_path / "rep" / "report.html").is_file() and (tmp_path / "rep" / "report.csv").is_file()


def test_rom_test_on_the_simulated_patient_stores_the_result(tmp_path, capsys):
    db = tmp_path / "r.sqlite3"
    run(capsys, "patients", "--add", "P001", "--db", db)
    code, out, err = run(capsys, "rom-test", "--patient", "P001", "--test", "forearm_supination", "--fps", "15",
                         "--db", db)
    assert code == 0, err
    assert "Forearm supination, right: 85 deg" in out and "active ROM" in out and "JARM normal 90" in out
    assert "stored result" in out
    with Database(db) as d:
        (r,) = d.rom_results("P001")
        (s,) = d.sessions("P001")
    # the simulated patient turns the palm up to 85 degrees (true markers read 85.0)
    assert abs(r.value_deg - 85.0) <= 3.0 and r.mode == "active" and r.standard == "jarm"
    assert (r.test, r.side, r.angle, r.position) == ("forearm_supination", "right", "right_forearm_supination",
                                                     "seated_arm_at_side_elbow_90")
    assert r.reference_deg == 90 and r.compensation == "" and s.kind == "rom" and s.ended_utc
    # committed durably: a plain sqlite3 reader sees it
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT count(*) FROM rom_results").fetchone()[0] == 1


def test_rom_test_says_whether_the_change_from_the_previous_session_is_real(tmp_path, capsys):
    import re

    from game.rom.session import RomResult
    from game.rom.spec import load_rom_test

    db = tmp_path / "r.sqlite3"
    with Database(db) as d:
        d.add_patient("P001")
        s = d.start_session("P001", "rom", started_utc="2026-11-01T09:00:00Z")
        d.add_rom_result(s, RomResult(
            test="forearm_supination", title="Forearm supination", side="right", angle="right_forearm_supination",
            direction=1, mode="active", position="seated_arm_at_side_elbow_90", position_words="x", standard="jarm",
            reference_deg=90.0, max_deg=80.0, start_deg=0.0, range_deg=80.0, max_time_s=3.0, started_s=1.0,
            ended_s=6.0, compensations=(), estimated_markers=(), n_samples=90))
    code, out, err = run(capsys, "rom-test", "--patient", "P001", "--test", "forearm_supination", "--fps", "15",
                         "--db", db)
    assert code == 0, err
    sdc = load_rom_test("forearm_supination").sdc_deg
    m = re.search(r"change from the previous session: \+(\d+) degrees: within the measurement's smallest detectable "
                  r"change of (\d+) degrees \u2014 not a real change yet", out)
    assert m and int(m.group(2)) == round(sdc) and int(m.group(1)) < sdc, out

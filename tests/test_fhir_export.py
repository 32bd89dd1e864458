"""``rehab export --fhir``: one validated FHIR Bundle per patient, values, units and codes as stored,
nothing that identifies the patient, private files, and the CSV export unchanged beside it."""

from __future__ import annotations

import json
import stat

import pytest
from fhir.resources.R4B.bundle import Bundle

from calibration.errors import RehabError
from game.cli import main
from game.db import Database
from game.fhir_export import BODY_SITES, ROM_CODE, export_fhir, validate_bundle
from game.rom.session import RomResult


def rom_result(test="shoulder_flexion", side="right", value=120.0, reference=180.0, comp=(), est=(),
               position="seated_arm_at_side", angle=None) -> RomResult:
    return RomResult(test=test, title=test, side=side, angle=angle or f"{side}_{test}", direction=1, mode="active",
                     position=position, position_words="Seated.", standard="jarm", reference_deg=reference,
                     max_deg=value, start_deg=-4.25, range_deg=value + 4.25, max_time_s=3.0, started_s=1.0,
                     ended_s=6.0, compensations=comp, estimated_markers=est, n_samples=150)


NOTE = "Referred by Dr Smith, likes blue"


@pytest.fixture()
def db(tmp_path):
    db = Database(tmp_path / "db.sqlite3")
    db.add_patient("P001", NOTE)
    db.add_patient("P002")
    db.add_patient("P003")   # no ROM results: no bundle
    s = db.start_session("P001", "rom", started_utc="2026-01-05T09:00:00Z", source="sim:shoulder_flexion")
    db.add_rom_result(s, rom_result(value=131.37), recorded_utc="2026-01-05T09:05:00Z")
    db.add_rom_result(s, rom_result(test="elbow_flexion", side="left", value=141.0, reference=145.0,
                                    comp=("the trunk leaned",)), recorded_utc="2026-01-05T09:07:00Z")
    s = db.start_session("P001", "rom", started_utc="2026-02-05T09:00:00Z", source="cameras")
    # external rotation with the AAOS value of another position: no reference stored, none exported
    db.add_rom_result(s, rom_result(test="forearm_pronation", value=77.5, reference=None, est=("MRW2",),
                                    angle="right_forearm_supination", position="seated_arm_at_side_elbow_90"),
                      recorded_utc="2026-02-05T09:05:00Z")
    s = db.start_session("P002", "rom", started_utc="2026-01-06T09:00:00Z", source="sim:x")
    db.add_rom_result(s, rom_result(value=99.0), recorded_utc="2026-01-06T09:05:00Z")
    yield db
    db.close()


def _observations(bundle: dict) -> list[dict]:
    return [e["resource"] for e in bundle["entry"] if e["resource"]["resourceType"] == "Observation"]


def test_the_export_validates_and_carries_the_stored_values(db, tmp_path):
    counts = export_fhir(db, tmp_path / "out")
    assert counts == {"bundles": 2, "observations": 4}
    folder = tmp_path / "out" / "fhir"
    assert sorted(p.name for p in folder.iterdir()) == ["P001.json", "P002.json"]
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    text = (folder / "P001.json").read_text(encoding="utf-8")
    assert stat.S_IMODE((folder / "P001.json").stat().st_mode) == 0o600
    model = Bundle.model_validate_json(text)             # the written file is valid FHIR as it stands
    assert model.type == "collection"
    bundle = json.loads(text)
    rows = {r.uid: r for r in db.rom_results("P001")}
    obs = _observations(bundle)
    assert len(obs) == len(rows) == 3
    devices = {e["fullUrl"]: e["resource"] for e in bundle["entry"] if e["resource"]["resourceType"] == "Device"}
    assert len(devices) == 2   # the simulated patient's sessions and the cameras'
    for o in obs:
        (ident,) = o["identifier"]
        row = rows[ident["value"].removeprefix("urn:uuid:").replace("-", "")]
        assert o["status"] == "final" and o["effectiveDateTime"] == row.recorded_utc
        assert o["code"]["coding"] == [{"system": "http://snomed.info/sct", "code": ROM_CODE[0],
                                        "display": ROM_CODE[1]}]
        q = o["valueQuantity"]
        assert (q["unit"], q["system"], q["code"]) == ("deg", "http://unitsofmeasure.org", "deg")
        assert q["value"] == pytest.approx(row.value_deg, abs=0.005)
        comps = {c["code"]["text"]: c for c in o["component"]}
        assert comps["start angle"]["valueQuantity"]["value"] == pytest.approx(row.start_deg, abs=0.005)
        assert comps["movement from the start angle"]["valueQuantity"]["value"] == pytest.approx(row.range_deg, abs=0.005)
        assert comps["test position"]["valueString"].startswith(row.position + ": ")
        assert o["method"]["text"].startswith("active range of motion")
        assert o["device"]["reference"] in devices
        (site,) = o["bodySite"]["coding"]
        joint = {"shoulder_flexion": "shoulder", "elbow_flexion": "elbow", "forearm_pronation": "forearm"}[row.test]
        assert site["code"] == BODY_SITES[joint][row.side][0] and row.side in site["display"].lower()
        if row.reference_deg is None:
            assert "referenceRange" not in o
        else:
            (ref,) = o["referenceRange"]
            assert ref["high"]["value"] == row.reference_deg and ref["high"]["code"] == "deg"
            assert ref["low"]["value"] == pytest.approx(0.9 * row.reference_deg)
    by_test = {o["code"]["text"]: o for o in obs}
    assert by_test["Shoulder flexion, active range of motion"]["bodySite"]["coding"][0]["code"] == "91774008"
    assert by_test["Elbow flexion, active range of motion"]["bodySite"]["coding"][0]["code"] == "368148009"
    assert by_test["Elbow flexion, active range of motion"]["note"] == [{"text": "compensation seen: the trunk leaned"}]
    assert "MRW2" in by_test["Forearm pronation, active range of motion"]["note"][0]["text"]


def test_nothing_identifies_the_patient(db, tmp_path):
    export_fhir(db, tmp_path / "out", "P001")
    assert [p.name for p in (tmp_path / "out" / "fhir").iterdir()] == ["P001.json"]
    text = (tmp_path / "out" / "fhir" / "P001.json").read_text(encoding="utf-8")
    bundle = json.loads(text)
    assert "Smith" not in text and "blue" not in text and "P002" not in text
    kinds = {e["resource"]["resourceType"] for e in bundle["entry"]}
    assert kinds == {"Observation", "Device"}        # no Patient resource: the pseudonymous ID only

    def keys(x):
        if isinstance(x, dict):
            for k, v in x.items():
                yield k
                yield from keys(v)
        elif isinstance(x, list):
            for v in x:
                yield from keys(v)

    # (the Device has a name: the capture system's)
    assert not {"name", "birthDate", "address", "telecom", "gender", "photo"} & set(keys(_observations(bundle)))
    for o in _observations(bundle):
        assert o["subject"] == {"type": "Patient", "identifier": {"value": "P001"}}


def test_an_invalid_bundle_is_one_line(db):
    with pytest.raises(RehabError) as info:
        validate_bundle({"resourceType": "Bundle", "type": "collection",
                         "entry": [{"resource": {"resourceType": "Observation", "status": "final",
                                                 "code": {"text": "x"}, "valueQuantity": {"value": "many"}}}]},
                        "x.json")
    assert "x.json: not valid FHIR" in str(info.value) and "\n" not in str(info.value)


def test_the_command_keeps_the_csv_export_as_it_was(db, tmp_path, capsys):
    db_path = db.path
    db.close()
    assert main(["export", "--out", str(tmp_path / "plain"), "--db", str(db_path)]) == 0
    plain_out = capsys.readouterr().out
    assert main(["export", "--out", str(tmp_path / "both"), "--fhir", "--db", str(db_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(plain_out.replace("plain", "both")) and "wrote 2 FHIR bundles (4 observations, validated)" in out
    plain = sorted(p.name for p in (tmp_path / "plain").iterdir())
    both = sorted(p.name for p in (tmp_path / "both").iterdir())
    assert both == sorted(plain + ["fhir"]) and "fhir" not in plain
    for name in plain:
        assert (tmp_path / "both" / name).read_bytes() == (tmp_path / "plain" / name).read_bytes()
    assert main(["export", "--out", str(tmp_path / "x"), "--fhir", "--patient", "P404", "--db", str(db_path)]) == 1
    err = capsys.readouterr().err
    assert "P404" in err and err.count("\n") == 1

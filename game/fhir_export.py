"""Accepted ROM results as HL7 FHIR R4 Observations, one collection Bundle per patient.

``rehab export --fhir`` writes ``fhir/<patient>.json`` beside the CSV files. Each stored (that
is, accepted) ROM result becomes one Observation: the value in degrees (UCUM ``deg``), the joint
and side as ``bodySite`` (a lateralised SNOMED CT body region), active ROM as ``method``, the test
position, the start angle and the movement from it as components, the standard's normal value for
that position as ``referenceRange`` (the normal band of the reports: the value down 10 %), the
capture system as a Device in the same bundle, and the patient as the pseudonymous ID only.
Every bundle is validated with ``fhir.resources`` before it is written (0600, whole or not at
all). The codes and their sources are listed in docs/ROM.md (FHIR export).

``fhir.resources`` 8 carries FHIR R4B (4.3) models, not 4.0.1: the parts used here (Bundle,
Observation, Device and their data types) did not change between R4 and R4B, so a bundle valid
there is a valid R4 bundle.
"""

from __future__ import annotations

import json
import uuid
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, Sequence

import pydantic

from calibration.errors import RehabError
from game.db.database import utc_now
from game.db.private import make_private_dir, open_private
from game.report import NORMAL_BAND_FRACTION
from game.rom.spec import STANDARDS, load_rom_test
from tracking.errors import ContentError

SNOMED = "http://snomed.info/sct"
UCUM = "http://unitsofmeasure.org"
OBSERVATION_CATEGORY = "http://terminology.hl7.org/CodeSystem/observation-category"
REFERENCE_RANGE_MEANING = "http://terminology.hl7.org/CodeSystem/referencerange-meaning"

#: SNOMED CT 364564000 |Range of joint movement (observable entity)|: the Observation's code
ROM_CODE = ("364564000", "Range of joint movement")

#: joint of the read angle -> side -> (SNOMED CT code, display) of the lateralised body region.
#: Regions, not joints: these pre-coordinated left/right concepts are the ones we could check.
BODY_SITES: dict[str, dict[str, tuple[str, str]]] = {
    "shoulder": {"right": ("91774008", "Structure of right shoulder region"),
                 "left": ("91775009", "Structure of left shoulder region")},
    "elbow": {"right": ("368149001", "Right elbow region structure"),
              "left": ("368148009", "Left elbow region structure")},
    "forearm": {"right": ("64262003", "Structure of right forearm"),
                "left": ("66480008", "Structure of left forearm")},
}

#: the capture system, as the Device of every Observation
DEVICE_NAME = "rehab-mocap colour-marker motion capture"


def _uuid_urn(seed: str) -> str:
    """A stable ``urn:uuid:`` for a stored uid (32 hex digits) or any other text."""
    try:
        return uuid.UUID(hex=seed).urn
    except ValueError:
        return uuid.uuid5(uuid.NAMESPACE_URL, f"rehab-mocap:{seed}").urn


def _joint(angle: str) -> str:
    """``right_shoulder_flexion`` or ``shoulder_flexion`` -> ``shoulder``."""
    name = angle.removeprefix("right_").removeprefix("left_")
    return name.split("_", 1)[0]


def _version() -> str:
    try:
        return metadata.version("rehab-mocap")
    except metadata.PackageNotFoundError:
        return "unknown"


def _deg(value: float) -> dict:
    return {"value": round(float(value), 2), "unit": "deg", "system": UCUM, "code": "deg"}


@dataclass(frozen=True, slots=True)
class _TestWords:
    title: str
    position_words: str


def _test_words(test: str) -> _TestWords:

    try:
        t = load_rom_test(test)
    except ContentError:   # a result of a test this installation does not define
        return _TestWords(test.replace("_", " ").capitalize(), "")
    return _TestWords(t.title, t.position_words)


def device_resource(source: str) -> dict:
    """The Device of the results of one session source (``sim:...`` is the simulated patient)."""
    simulated = source.startswith("sim")
    dev: dict[str, Any] = {
        "resourceType": "Device",
        "deviceName": [{"name": DEVICE_NAME, "type": "model-name"}],
        "type": {"text": "optical motion capture with coloured markers and several cameras"},
        "version": [{"value": _version()}],
    }
    if simulated:
        dev["note"] = [{"text": "measured on the built-in simulated patient (no person), rendered camera images"}]
    return dev


def observation(row, device_url: str, position_words: str, title: str) -> dict:
    """One stored ROM result (:class:`game.db.RomRow`) as an Observation (a dict of FHIR JSON)."""
    site = BODY_SITES.get(_joint(row.angle or row.test), {}).get(row.side)
    body_site: dict[str, Any] = {"text": f"{row.side} {_joint(row.angle or row.test)}"}
    if site is not None:
        body_site["coding"] = [{"system": SNOMED, "code": site[0], "display": site[1]}]
    position = position_words or row.position.replace("_", " ")
    obs: dict[str, Any] = {
        "resourceType": "Observation",
        "identifier": [{"system": "urn:ietf:rfc:3986", "value": _uuid_urn(row.uid)}],
        "status": "final",
        "category": [{"coding": [{"system": OBSERVATION_CATEGORY, "code": "exam", "display": "Exam"}]}],
        "code": {"coding": [{"system": SNOMED, "code": ROM_CODE[0], "display": ROM_CODE[1]}],
                 "text": f"{title}, {row.mode} range of motion"},
        "subject": {"type": "Patient", "identifier": {"value": row.patient_id}},
        "effectiveDateTime": row.recorded_utc,
        "valueQuantity": _deg(row.value_deg),
        "bodySite": body_site,
        "method": {"text": f"{row.mode} range of motion (the patient's own movement, nobody helps), "
                           f"the maximum measured by optical motion capture"},
        "device": {"reference": device_url},
        "component": [
            {"code": {"text": "test position"}, "valueString": f"{row.position}: {position}"},
            {"code": {"text": "start angle"}, "valueQuantity": _deg(row.start_deg)},
            {"code": {"text": "movement from the start angle"}, "valueQuantity": _deg(row.range_deg)},
        ],
    }
    if row.reference_deg is not None:
        normal = float(row.reference_deg)
        obs["referenceRange"] = [{
            "low": _deg(normal * (1.0 - NORMAL_BAND_FRACTION)), "high": _deg(normal),
            "type": {"coding": [{"system": REFERENCE_RANGE_MEANING, "code": "normal", "display": "Normal Range"}]},
            "text": f"normal value {normal:g} degrees in this test position, {STANDARDS.get(row.standard, row.standard)}; "
                    f"the range is the normal value down {NORMAL_BAND_FRACTION:.0%}",
        }]
    notes = []
    if row.compensation:
        notes.append(f"compensation seen: {row.compensation}")
    if row.estimated_markers:
        notes.append(f"the maximum rested on estimated (hidden) markers: {row.estimated_markers}")
    if notes:
        obs["note"] = [{"text": n} for n in notes]
    return obs


def patient_bundle(patient_id: str, rows: Sequence, sources: dict[str, str], timestamp: str) -> dict:
    """The collection Bundle of one patient's ROM results (FHIR JSON as a dict, not yet validated).

    Args:
        rows: the patient's :class:`game.db.RomRow` (every stored result is an accepted one).
        sources: session uid -> the session's source (``sim:...`` or a camera description).
        timestamp: the bundle's time stamp (ISO 8601 UTC).
    """
    entries: list[dict] = []
    devices: dict[str, str] = {}
    observations = []
    words: dict[str, _TestWords] = {}
    for row in rows:
        kind = "sim" if sources.get(row.session_uid, "").startswith("sim") else "cameras"
        if kind not in devices:
            devices[kind] = _uuid_urn(f"device:{kind}:{_version()}")
            entries.append({"fullUrl": devices[kind], "resource": device_resource(kind)})
        w = words.setdefault(row.test, _test_words(row.test))
        observations.append({"fullUrl": _uuid_urn(row.uid),
                             "resource": observation(row, devices[kind], w.position_words, w.title)})
    return {"resourceType": "Bundle", "identifier": {"system": "urn:ietf:rfc:3986",
                                                     "value": _uuid_urn(f"bundle:{patient_id}:{timestamp}")},
            "type": "collection", "timestamp": timestamp, "entry": entries + observations}


def validate_bundle(bundle: dict, where: str) -> None:
    """Check a bundle against the FHIR models of ``fhir.resources``.

    Raises:
        RehabError: the bundle is not valid FHIR (a bug: the message names the first problem).
    """
    try:
        # lazy: fhir.resources (0.2 s) only to validate; a one-line error when missing
        from fhir.resources.R4B.bundle import Bundle
    except ImportError:
        raise RehabError("the FHIR export needs fhir.resources: pip install 'fhir.resources>=8'") from None

    try:
        Bundle.model_validate(bundle)
    except pydantic.ValidationError as exc:
        first = exc.errors()[0]
        raise RehabError(f"{where}: not valid FHIR ({'.'.join(map(str, first['loc']))}: {first['msg']}): "
                         f"please report this") from None


def export_fhir(db, out_dir: str | Path, patient_id: str | None = None) -> dict[str, int]:
    """Write one validated FHIR Bundle per patient with ROM results to ``out_dir/fhir/<patient>.json``.

    ``patient_id`` None exports everyone (patients without ROM results get no file). Returns
    ``{"bundles": ..., "observations": ...}``.
    """

    if patient_id is not None:
        db.require_patient(patient_id)
    folder = make_private_dir(Path(out_dir) / "fhir")
    stamp = utc_now()
    counts = {"bundles": 0, "observations": 0}
    for patient in db.patients():
        if patient_id is not None and patient.id != patient_id:
            continue
        rows = db.rom_results(patient.id)
        if not rows:
            continue
        sources = {s.uid: s.source for s in db.sessions(patient.id)}
        bundle = patient_bundle(patient.id, rows, sources, stamp)
        path = folder / f"{patient.id}.json"
        validate_bundle(bundle, str(path))
        try:
            with open_private(path, "w", encoding="utf-8") as fh:
                json.dump(bundle, fh, indent=1, ensure_ascii=False, allow_nan=False)
                fh.write("\n")
        except OSError as exc:
            raise RehabError(f"{path}: cannot write the FHIR bundle ({exc.strerror or exc}): check the folder") from None
        counts["bundles"] += 1
        counts["observations"] += len(rows)
    return counts

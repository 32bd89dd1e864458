"""Identification sweep: the reference pose over body sizes, arm perturbations and camera layouts.

``python -m tracking.sim.identify_sweep`` renders the reference pose (docs/METHOD.md 5.2) for
several bodies (5th percentile woman to 95th percentile man), each with the arms perturbed (each
arm's shoulder flexion, abduction and axial rotation and the elbow flexion moved by up to +-10
degrees: a few corner combinations and seeded random ones), in every camera layout of
``content/rigs``, and runs the :class:`tracking.tracker.Tracker` on it for a few frames (each
frame with its own sensor noise). Every marker the tracker names is compared with the
simulator's truth. Deliberately wrong poses (upper arms against the body with the hands on the
thighs, arms crossed, arms raised) must leave the tracker waiting with a message, never with
names; the message should be the broken rule's therapist message (it is the point counts when
the pose hides markers and the seen ones keep the rules).

A case *passes* when the tracker names every marker and every name is right. A case in which
some markers are named right and the others (seen by one camera only) are left for re-acquisition
is *partly named*; a case that stays waiting is counted apart too; a wrong name is a failure
whatever else. A rig is PASS when every case passes, PASS-PARTLY when every case is named (some
partly) without a wrong name and no wrong pose is named, FAIL otherwise. Poses a body cannot take
(a wrist ball inside the chair seat) are not run.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Iterable, Iterator, Sequence

import numpy as np

from tracking.colour.table import ColourTable
from tracking.content_loader import available
from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.body import (
    REFERENCE_ABDUCTION_DEG,
    REFERENCE_ELBOW_FLEXION_DEG,
    REFERENCE_EXTERNAL_ROTATION_DEG,
    REFERENCE_SUPINATION_DEG,
    ArmPose,
    BodyDimensions,
    BodyModel,
    Pose,
    reference_arm,
)
from tracking.sim.rigs import load_rig
from tracking.sim.room import SEAT_TOP_M
from tracking.sim.studio import Studio
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackingState

#: (percentile, sex) of the swept bodies.
BODIES: tuple[tuple[float, str], ...] = ((5, "female"), (50, "female"), (50, "male"), (95, "male"))

#: A named marker is right when it lies this near to its own true position.
NAME_TOLERANCE_M = 0.015
#: A named marker farther than NAME_TOLERANCE_M from its ball but nearer to it than to any other
#: marker and within this distance is badly measured (a ball seen only partly), not misnamed.
MEASURE_TOLERANCE_M = 0.04

#: Half width and depth of the chair seat of the simulated room (tracking/sim/room.py).
SEAT_HALF_SIZE_M = 0.23


def seat_clash(body: BodyModel, pose: Pose, markerset: MarkerSet) -> tuple[str, ...]:
    """Markers whose ball would be inside the chair seat (the body model does not stop the hand).

    A small body with the arm hanging close to the side, straight and slightly back puts the wrist
    beside the hip at seat level: the hand would rest on the seat instead, so the pose cannot be
    taken as perturbed.
    """
    p = body.markers_m(pose)
    r = markerset.radius_m
    inside = ((np.abs(p[:, 0]) < SEAT_HALF_SIZE_M + r) & (np.abs(p[:, 2]) < SEAT_HALF_SIZE_M + r)
              & (p[:, 1] - r < SEAT_TOP_M))
    return tuple(n for n, k in zip(markerset.names, inside) if k)


@dataclass(frozen=True, slots=True)
class ArmDelta:
    """Change of one arm from the reference pose, degrees (right-side convention, see body.py)."""

    flexion_deg: float = 0.0
    abduction_deg: float = 0.0
    rotation_deg: float = 0.0
    elbow_deg: float = 0.0

    def arm(self) -> ArmPose:
        return reference_arm(REFERENCE_ABDUCTION_DEG + self.abduction_deg, self.flexion_deg,
                             REFERENCE_EXTERNAL_ROTATION_DEG + self.rotation_deg,
                             REFERENCE_ELBOW_FLEXION_DEG + self.elbow_deg, REFERENCE_SUPINATION_DEG)


@dataclass(frozen=True, slots=True)
class SweepPose:
    """A named pose of the sweep: the reference pose perturbed, or a deliberately wrong pose."""

    name: str
    pose: Pose
    wrong: bool = False


def perturbed_poses(n_corners: int = 6, n_random: int = 4, deg: float = 10.0, seed: int = 0) -> list[SweepPose]:
    """The reference pose, then perturbed ones.

    Args:
        n_corners: poses at corners of the +-``deg`` box of the 8 angles (4 per arm). The first
            two corners are all + and all - on both arms; the rest are seeded random corners.
        n_random: poses with each of the 8 angles uniform in +-``deg`` (seeded).
        deg: the largest change of each angle.
        seed: random seed.
    """
    rng = np.random.default_rng(seed)
    out = [SweepPose("reference", Pose(right=ArmDelta().arm(), left=ArmDelta().arm()))]
    corners = [np.full(8, 1.0), np.full(8, -1.0)]
    corners += [rng.choice([-1.0, 1.0], 8) for _ in range(max(n_corners - 2, 0))]
    for k, signs in enumerate(corners[:n_corners]):
        right, left = ArmDelta(*(deg * signs[:4])), ArmDelta(*(deg * signs[4:]))
        out.append(SweepPose(f"corner{k + 1} R{_signs(signs[:4])} L{_signs(signs[4:])}",
                             Pose(right=right.arm(), left=left.arm())))
    for k in range(n_random):
        d = rng.uniform(-deg, deg, 8)
        right, left = ArmDelta(*d[:4]), ArmDelta(*d[4:])
        out.append(SweepPose(f"random{k + 1}", Pose(right=right.arm(), left=left.arm())))
    return out


def _signs(signs: np.ndarray) -> str:
    return "".join("+" if s > 0 else "-" for s in signs)


def wrong_poses() -> list[SweepPose]:
    """Poses that break the reference-pose rules; the tracker must explain, not name."""
    lap = ArmPose.clinical(20.0, 0.0, -30.0, 70.0, 0.0)  # upper arms against the body, hands on the thighs
    crossed = ArmPose.clinical(40.0, -20.0, -60.0, 90.0, 0.0)
    raised = ArmPose.clinical(0.0, 150.0, 0.0, 0.0, 0.0)
    return [
        SweepPose("arms against the body", Pose(right=lap, left=lap), wrong=True),
        SweepPose("arms crossed", Pose(right=crossed, left=crossed), wrong=True),
        SweepPose("arms raised", Pose(right=raised, left=raised), wrong=True),
    ]


@dataclass(frozen=True, slots=True)
class CaseResult:
    """What the tracker made of one pose of one body in one layout.

    Attributes:
        rig, body, pose: the case (body as e.g. "p5 female").
        wrong_pose: the pose breaks the rules on purpose.
        identified_frame: frame of identification, -1 if the tracker kept waiting.
        named: markers named (measured or estimated) after the last frame.
        wrong: names of markers placed on something else than their ball (another marker's ball,
            or farther than MEASURE_TOLERANCE_M).
        inaccurate: names of markers on their own ball but measured more than NAME_TOLERANCE_M off.
        unseen: names of markers left unnamed (lost) after the last frame.
        message: the tracker's last message while waiting ("" once identified).
        rule_message: the message is one of the marker set's rule messages (a therapist message).
        clash: markers that would be inside the chair seat: the pose cannot be taken and the case
            was not run (counted apart).
        cameras: the rig's number of cameras.
    """

    rig: str
    body: str
    pose: str
    wrong_pose: bool
    identified_frame: int
    named: int
    wrong: tuple[str, ...]
    unseen: tuple[str, ...]
    message: str
    rule_message: bool
    clash: tuple[str, ...] = ()
    inaccurate: tuple[str, ...] = ()
    cameras: int = 0

    @property
    def identified(self) -> bool:
        return self.identified_frame >= 0

    @property
    def passed(self) -> bool:
        """Every marker named right (a reference pose), or waiting with a message (a wrong one)."""
        if self.wrong_pose:
            return not self.identified and bool(self.message)
        return self.identified and not self.wrong and not self.unseen


def body_label(p: float, sex: str) -> str:
    return f"p{p:g} {sex}"


def run_case(studio: Studio, tracker: Tracker, rig: str, body: str, case: SweepPose, *, frames: int = 3,
             noise_sigma: float = 1.5, seed: int = 0) -> CaseResult:
    """Render ``case.pose`` ``frames`` times after the tracker's hold (fresh noise each) and track it
    from a reset tracker."""
    ms = studio.markerset
    clash = seat_clash(studio.body, case.pose, ms)
    if clash:
        return CaseResult(rig, body, case.name, case.wrong, -1, 0, (), (), "", False, clash=clash,
                          cameras=len(tracker.cameras))
    tracker.reset()
    identified_frame, message, sample, truth = -1, "", None, None
    for k in range(frames + tracker.hold_frames):
        sf = studio.render(case.pose, k, k / tracker.fps, noise_sigma=noise_sigma, seed=seed * 1009 + k,
                           with_visibility=False)
        sample = tracker.step(sf.frames.images)
        truth = sf.markers_m
        if sample.state == TrackingState.TRACKING:
            if identified_frame < 0:
                identified_frame = k
        else:
            message = sample.message
    named_mask = sample.status != MarkerStatus.LOST
    d = np.linalg.norm(sample.positions_m - truth, axis=1)
    to_all = np.linalg.norm(sample.positions_m[:, None, :] - truth[None, :, :], axis=-1)
    own_ball = np.nan_to_num(to_all, nan=np.inf).argmin(axis=1) == np.arange(len(d))
    off = named_mask & ~(d < NAME_TOLERANCE_M)
    near = own_ball & (d < MEASURE_TOLERANCE_M)
    wrong = tuple(n for n, k in zip(ms.names, off & ~near) if k)
    inaccurate = tuple(n for n, k in zip(ms.names, off & near) if k)
    unseen = tuple(n for n, ok in zip(ms.names, named_mask) if not ok) if identified_frame >= 0 else ()
    rules = ms.identification.rules if ms.identification is not None else ()
    rule_message = any(message.startswith(r.message) for r in rules)
    return CaseResult(rig, body, case.name, case.wrong, identified_frame, int(named_mask.sum()), wrong, unseen,
                      message if identified_frame < 0 else "", rule_message, inaccurate=inaccurate,
                      cameras=len(tracker.cameras))


def sweep(rigs: Sequence[str], bodies: Sequence[tuple[float, str]] = BODIES,
          poses: Sequence[SweepPose] | None = None, *, size_px: tuple[int, int] = (640, 480), frames: int = 3,
          markerset: MarkerSet | None = None, noise_sigma: float = 1.5) -> Iterator[CaseResult]:
    """Every pose of every body in every rig; yields one :class:`CaseResult` per case."""
    ms = markerset or load_markerset()
    table = ColourTable.build(ms.palette)
    poses = list(poses) if poses is not None else perturbed_poses() + wrong_poses()
    for rig in rigs:
        cameras = load_rig(rig, size_px)
        tracker = Tracker(cameras, ms, table=table, fps=15.0)
        for p, sex in bodies:
            with Studio(cameras, ms, BodyDimensions.from_percentile(p, sex)) as studio:
                for k, case in enumerate(poses):
                    yield run_case(studio, tracker, rig, body_label(p, sex), case, frames=frames,
                                   noise_sigma=noise_sigma, seed=k)


def _short(text: str, n: int = 90) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def table_markdown(results: Sequence[CaseResult]) -> str:
    """Two markdown tables: reference poses (rig x body) and wrong poses (rig x pose)."""
    skipped = [r for r in results if r.clash]
    ref = [r for r in results if not r.wrong_pose and not r.clash]
    bad = [r for r in results if r.wrong_pose and not r.clash]
    lines = []
    if ref:
        bodies = list(dict.fromkeys(r.body for r in ref))
        lines += ["| rig | " + " | ".join(bodies) + " |", "| --- |" + " --- |" * len(bodies)]
        for rig in dict.fromkeys(r.rig for r in ref):
            cells = []
            for body in bodies:
                cell = [r for r in ref if r.rig == rig and r.body == body]
                cells.append(_cell(cell))
            lines.append(f"| {rig} | " + " | ".join(cells) + " |")
        lines.append("")
        lines.append("Cell: poses with every marker named right / poses; then what happened in the others "
                     "(partly named: names given are right, the unseen markers are left for re-acquisition; "
                     "waiting: the tracker's message; WRONG: misnamed markers; measured off: named right but "
                     "the point is more than 15 mm from the ball, a partly hidden ball).")
    if skipped:
        cases = sorted({(r.body, r.pose) for r in skipped})
        lines.append(f"Not run ({len(cases)} body-pose cases, in every rig): a wrist ball would be inside the chair "
                     "seat: " + "; ".join(f"{b} {p}" for b, p in cases) + ".")
    if bad:
        lines += ["", "| rig | pose | " + " | ".join(dict.fromkeys(r.body for r in bad)) + " |",
                  "| --- | --- |" + " --- |" * len(dict.fromkeys(r.body for r in bad))]
        for rig, pose in dict.fromkeys((r.rig, r.pose) for r in bad):
            cells = []
            for r in (r for r in bad if r.rig == rig and r.pose == pose):
                if r.identified:
                    cells.append(f"NAMED ({r.named} markers{', WRONG ' + ','.join(r.wrong) if r.wrong else ''})")
                else:
                    cells.append(("" if r.rule_message else "(counts) ") + _short(r.message, 70))
            lines.append(f"| {rig} | {pose} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _cell(cases: Sequence[CaseResult]) -> str:
    ok = sum(c.passed for c in cases)
    text = f"{ok}/{len(cases)}"
    wrong = sorted({n for c in cases for n in c.wrong})
    partly = [c for c in cases if c.identified and c.unseen and not c.wrong]
    waiting = [c for c in cases if not c.identified]
    notes = []
    if wrong:
        notes.append(f"WRONG {','.join(wrong)} in {sum(bool(c.wrong) for c in cases)}")
    if partly:
        unseen = sorted({n for c in partly for n in c.unseen})
        notes.append(f"{len(partly)} partly named (unseen {','.join(unseen)})")
    if waiting:
        notes.append(f"{len(waiting)} waiting: {_short(waiting[0].message, 60)}")
    inaccurate = sorted({n for c in cases for n in c.inaccurate})
    if inaccurate:
        notes.append(f"measured > {NAME_TOLERANCE_M * 1000:.0f} mm off: {','.join(inaccurate)}")
    return text + (" " + "; ".join(notes) if notes else "")


def rig_table(results: Sequence[CaseResult]) -> str:
    """A markdown table, one row per rig: reference-pose cases identified (every marker named /
    some left for re-acquisition), waited and misnamed; wrong poses not named (by a rule message)."""
    lines = ["| rig | cameras | reference cases | identified (all named + partly) | waited | misnamed "
             "| wrong poses not named (rule message) |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for rig in dict.fromkeys(r.rig for r in results):
        rr = [r for r in results if r.rig == rig and not r.clash]
        ref = [r for r in rr if not r.wrong_pose]
        bad = [r for r in rr if r.wrong_pose]
        named = [r for r in ref if r.identified]
        full = sum(not r.unseen for r in named)
        kept = sum(not r.identified and bool(r.message) for r in bad)
        lines.append(f"| {rig} | {rr[0].cameras if rr else ''} | {len(ref)} | {len(named)} ({full} + {len(named) - full}) "
                     f"| {len(ref) - len(named)} | {sum(bool(r.wrong) for r in rr)} "
                     f"| {kept}/{len(bad)} ({sum(r.passed and r.rule_message for r in bad)}) |")
    return "\n".join(lines)


def summary(results: Sequence[CaseResult]) -> str:
    """One line per rig: PASS (every reference pose fully named right, no wrong pose named),
    PASS-PARTLY (some reference poses named without their unseen markers, every name right) or FAIL."""
    out = []
    for rig in dict.fromkeys(r.rig for r in results):
        rr = [r for r in results if r.rig == rig and not r.clash]
        ref = [r for r in rr if not r.wrong_pose]
        bad = [r for r in rr if r.wrong_pose]
        full = sum(r.passed for r in ref)
        partly = sum(r.identified and bool(r.unseen) and not r.wrong for r in ref)
        waiting = sum(not r.identified for r in ref)
        wrong = sum(bool(r.wrong) for r in rr)
        bad_ok = all(r.passed for r in bad)
        if full == len(ref) and bad_ok:
            verdict = "PASS"
        elif full + partly == len(ref) and bad_ok:
            verdict = "PASS-PARTLY"
        else:
            verdict = "FAIL"
        out.append(f"{rig}: {verdict}  reference poses: every marker named right {full}/{len(ref)}, partly named "
                   f"{partly}, waiting {waiting}, wrong names {wrong}; wrong poses not named "
                   f"{sum(r.passed for r in bad)}/{len(bad)} (by a broken rule {sum(r.passed and r.rule_message for r in bad)})")
    return "\n".join(out)


def main(argv: Iterable[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tracking.sim.identify_sweep", description=__doc__.split("\n\n")[0])
    parser.add_argument("--rig", action="append", default=None, help="rig name or YAML (repeat; default: every built-in rig)")
    parser.add_argument("--size", default="640x480", help="image size WxH (default: %(default)s)")
    parser.add_argument("--frames", type=int, default=3, help="frames tracked per case (default: %(default)s)")
    parser.add_argument("--corners", type=int, default=6, help="corner perturbations per body (default: %(default)s)")
    parser.add_argument("--random", type=int, default=4, help="random perturbations per body (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="bodies p5 female and p95 male, 2 corners, 1 random")
    parser.add_argument("--body", action="append", default=None, metavar="PCT:SEX",
                        help="body as percentile:sex, e.g. 95:male (repeat; default: p5 and p50 female, p50 and p95 male)")
    args = parser.parse_args(list(argv) if argv is not None else None)
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        parser.error(f"--size {args.size}: give WxH, e.g. 640x480")
    if args.frames < 1:
        parser.error(f"--frames {args.frames}: give 1 or more")
    rigs = args.rig or available("rigs")
    bodies = ((5, "female"), (95, "male")) if args.quick else BODIES
    if args.body:
        try:
            bodies = tuple((float(b.split(":")[0]), b.split(":")[1]) for b in args.body)
        except (ValueError, IndexError):
            parser.error(f"--body {args.body}: give percentile:sex, e.g. 95:male")
        if any(sex not in ("female", "male") or not 0 < p < 100 for p, sex in bodies):
            parser.error(f"--body {args.body}: the percentile is in 1-99 and the sex female or male")
    corners, rand = (2, 1) if args.quick else (args.corners, args.random)
    poses = perturbed_poses(corners, rand, seed=args.seed) + wrong_poses()
    results = []
    total = len(rigs) * len(bodies) * len(poses)
    for n, r in enumerate(sweep(rigs, bodies, poses, size_px=(w, h), frames=args.frames), 1):
        results.append(r)
        print(f"\r{n}/{total} {r.rig} {r.body} {r.pose}".ljust(70), end="", file=sys.stderr, flush=True)
    print("", file=sys.stderr)
    print(table_markdown(results))
    print()
    print(rig_table(results))
    print()
    print(summary(results))
    return 0 if all(r.passed for r in results if not r.clash) else 1


if __name__ == "__main__":
    raise SystemExit(main())

"""Camera layouts for identification: a grid search over camera places around the patient.

Identification needs a 3D point for (nearly) every marker of the reference pose, so every marker
must be seen well by two cameras. The inner elbow and wrist markers are the hard ones: they face
the trunk and the thighs. ``python -m tracking.sim.layout_search`` renders the reference pose of
several bodies with the arms perturbed (as :mod:`tracking.sim.identify_sweep` does) from a grid
of candidate camera places at once (one offscreen atlas per pose), keeps every marker's visible
fraction per candidate, and scores layouts made of the candidates:

- a marker is *seen* by a layout when one camera sees >= ``whole`` of its ball and another
  >= ``part`` (what the two-camera gates of the measurement accept), or three cameras see
  >= ``part``; a camera whose disc of the marker touches another ball of its colour sees neither;
- identification names the markers with up to three unseen (the tracker finds those later), so a
  layout's cost is the number of cases (body and pose) with more than three markers not seen, then
  the number of (case, marker) not seen, then the worst second-best visible fraction.

Four-camera layouts are two pairs mirrored about the patient's midline, three-camera layouts a
mirrored pair and one more camera; the two cameras of a pair stand at different heights (a
mirror-symmetric pair puts ghost points on the midline, docs/MEASUREMENT.md). The best layouts
are printed as rig YAML lines; check them with ``python -m tracking.sim.identify_sweep``, which
runs the real measurement and tracker.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.body import BodyDimensions
from tracking.sim.identify_sweep import BODIES, SweepPose, perturbed_poses, seat_clash
from tracking.sim.studio import Studio


@dataclass(frozen=True, slots=True)
class Place:
    """A candidate camera place (the rig YAML's numbers)."""

    azimuth_deg: float
    distance_m: float
    height_m: float

    def yaml(self, name: str) -> str:
        return (f"  - {{name: {name}, azimuth_deg: {self.azimuth_deg:g}, distance_m: {self.distance_m:g}, "
                f"height_m: {self.height_m:g}}}")


def place_camera(place: Place, size_px: tuple[int, int], fov_deg: float, target_m: Sequence[float]) -> Camera:
    """The camera of a place, aimed at ``target_m`` (as :func:`tracking.sim.rigs.load_rig` does)."""
    w, _ = size_px
    f_px = (w / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    az = np.radians(place.azimuth_deg)
    eye = (place.distance_m * np.sin(az), place.height_m, -place.distance_m * np.cos(az))
    return Camera.look_at(f"az{place.azimuth_deg:g}_d{place.distance_m:g}_h{place.height_m:g}", size_px, f_px, eye,
                          target_m)


def visibility(places: Sequence[Place], poses: Sequence[SweepPose], bodies: Sequence[tuple[float, str]], *,
               markerset: MarkerSet | None = None, size_px: tuple[int, int] = (400, 300), fov_deg: float = 55.0,
               target_m: Sequence[float] = (0.0, 0.95, 0.0), progress: bool = False) -> np.ndarray:
    """(cases, places, markers) visible fraction of each marker's ball from each place.

    Cases are bodies x poses, body-major, without the poses a body cannot take (a wrist inside
    the chair seat, :func:`tracking.sim.identify_sweep.seat_clash`). A view of a ball whose disc
    touches another ball of the same colour counts as 0 (one merged blob is a view of neither),
    and so does a ball outside the image.
    """
    ms = markerset or load_markerset()
    cameras = [place_camera(p, size_px, fov_deg, target_m) for p in places]
    out = []
    for p, sex in bodies:
        with Studio(cameras, ms, BodyDimensions.from_percentile(p, sex)) as studio:
            for case in poses:
                if seat_clash(studio.body, case.pose, ms):
                    continue
                sf = studio.render(case.pose, 0, 0.0)
                out.append(np.where(sf.merged, 0.0, sf.visible_fraction))
                if progress:
                    print(f"\rrendered {len(out)}/{len(bodies) * len(poses)}", end="", file=sys.stderr, flush=True)
    if progress:
        print("", file=sys.stderr)
    return np.stack(out)


def layout_cost(vis: np.ndarray, *, whole: float = 0.9, part: float = 0.8, max_unseen: int = 3
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cost of layouts.

    Args:
        vis: (L, K, cases, markers) visible fraction of each marker from each of the K cameras of
            L layouts.
        max_unseen: markers per case that identification may leave unseen
            (:meth:`tracking.labelling.rules.Identifier.identify_with_unseen`).

    Returns:
        (L,) int cases with more than ``max_unseen`` markers not seen; (L,) int (case, marker)
        not seen; (L,) float worst "second view" over the cases (the second-best fraction where
        the best is >= ``whole``, else 0; the third-best counts where it is higher).
    """
    v = -np.sort(-vis, axis=1)  # cameras by visibility, best first
    second = np.where(v[:, 0] >= whole, v[:, 1], 0.0)
    if v.shape[1] >= 3:
        second = np.maximum(second, np.where(v[:, 2] >= part, v[:, 2], 0.0))
    unseen = (second < part).sum(axis=2)  # (L, cases)
    return (unseen > max_unseen).sum(axis=1), unseen.sum(axis=1), second.min(axis=(1, 2))


def mirrored_pairs(places: Sequence[Place], min_height_step_m: float = 0.2) -> list[tuple[int, int]]:
    """Index pairs (a, b) of places mirrored about the midline, at different heights."""
    index = {(p.azimuth_deg, p.distance_m, p.height_m): i for i, p in enumerate(places)}
    heights = sorted({p.height_m for p in places})
    out = []
    for i, p in enumerate(places):
        if not 0 < p.azimuth_deg < 180:
            continue
        for h in heights:
            j = index.get((-p.azimuth_deg, p.distance_m, h))
            if j is not None and abs(h - p.height_m) >= min_height_step_m - 1e-9:
                out.append((i, j))
    return out


def best_layouts(vis: np.ndarray, places: Sequence[Place], n_cameras: int, *, max_abs_azimuth: float = 180.0,
                 top: int = 5, chunk: int = 4096) -> list[tuple[int, int, float, tuple[int, ...]]]:
    """The best layouts of ``n_cameras`` (4: two mirrored pairs; 3: a mirrored pair and one more).

    Args:
        vis: (cases, places, markers) from :func:`visibility`.
        places: the candidate places.
        max_abs_azimuth: only places with |azimuth| up to this (e.g. 100: nothing behind the patient).

    Returns:
        [(cases with too many markers unseen, (case, marker) unseen, worst second view, place
        indices)], best first.
    """
    allowed = [abs(p.azimuth_deg) <= max_abs_azimuth + 1e-9 for p in places]
    pairs = [pr for pr in mirrored_pairs(places) if allowed[pr[0]] and allowed[pr[1]]]
    if n_cameras == 4:
        combos = ((*a, *b) for a, b in itertools.combinations(pairs, 2) if len({*a, *b}) == 4)
    elif n_cameras == 3:
        singles = [i for i, ok in enumerate(allowed) if ok]
        combos = ((*a, s) for a in pairs for s in singles if s not in a)
    else:
        raise ValueError("n_cameras must be 3 or 4")
    vt = vis.transpose(1, 0, 2)  # (places, cases, markers)
    best: list[tuple[int, float, tuple[int, ...]]] = []
    while True:
        block = list(itertools.islice(combos, chunk))
        if not block:
            break
        idx = np.array(block)
        over, missed, second = layout_cost(vt[idx])
        order = np.lexsort((-second, missed, over))[:top]
        best += [(int(over[k]), int(missed[k]), float(second[k]), tuple(int(i) for i in idx[k])) for k in order]
        best = sorted(best, key=lambda r: (r[0], r[1], -r[2]))[:top]
    return best


def default_places() -> list[Place]:
    """Tripod and wall places: every 15 degrees, 1.3-2.5 m high, 1.9 and 2.3 m from the patient."""
    return [Place(float(a), d, h) for a in range(-165, 181, 15) for d in (1.9, 2.3) for h in (1.3, 1.6, 1.9, 2.2, 2.5)]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tracking.sim.layout_search", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cameras", type=int, choices=(3, 4), action="append", default=None)
    parser.add_argument("--max-azimuth", type=float, action="append", default=None,
                        help="|azimuth| limit in degrees (repeat; default: 180 and 100 = nothing behind)")
    parser.add_argument("--fov", type=float, default=55.0, help="horizontal field of view, degrees (default: %(default)s)")
    parser.add_argument("--top", type=int, default=5)
    parser.add_argument("--save", default=None, help="save the visibility table (.npz) here")
    parser.add_argument("--load", default=None, help="use a saved visibility table")
    args = parser.parse_args(argv)
    places = default_places()
    if args.load:
        vis = np.load(args.load)["vis"]
    else:
        vis = visibility(places, perturbed_poses(n_corners=6, n_random=0), BODIES, fov_deg=args.fov, progress=True)
        if args.save:
            np.savez_compressed(args.save, vis=vis)
    for n in args.cameras or (4, 3):
        for limit in args.max_azimuth or (180.0, 100.0):
            print(f"# {n} cameras, |azimuth| <= {limit:g}")
            for over, missed, second, idx in best_layouts(vis, places, n, max_abs_azimuth=limit, top=args.top):
                print(f"#   {over} cases with more than 3 markers unseen, {missed} markers unseen in all")
                for k, i in enumerate(idx, 1):
                    print(places[i].yaml(f"cam{k}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

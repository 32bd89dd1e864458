"""Self-checks of the named markers, every frame: anatomy that holds in any pose.

Per arm:

- **Elbow side**: with the elbow flexed (at least ``min_flexion_deg``), the plane of shoulder,
  elbow and wrist has the elbow's flexion axis for normal, and the lateral epicondyle marker lies
  on the side the arm's handedness fixes (the right arm's at -n, the left's at +n for
  n = (shoulder - elbow) x (wrist - elbow)). An exchanged pair of elbow markers puts it on the
  other side.
- **Forearm rotation**: the radial styloid marker's direction about the forearm, from the lateral
  epicondyle's (:func:`tracking.labelling.prior.forearm_rotation_deg`), stays within the forearm's
  range (full supination to full pronation). An exchanged pair of elbow or wrist markers turns it
  by 180 degrees: out of the range unless the forearm was near an end of it.

A check that fails names what to do: exchange the pair back when the exchanged reading keeps the
check clearly (``relabel``; the elbow pair when its side is clearly wrong, the wrist pair when the
elbow's side is clearly right), else mark the markers suspect (the tracker withholds the angles
that need them and says why).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.labelling import prior as bm
from tracking.labelling.roles import BodyRoles


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One frame's self-checks.

    Attributes:
        suspect: (M,) bool markers whose names the checks doubt.
        relabel: pairs (i, j) of markers whose names are exchanged, to exchange back.
        reason: one line on the failed checks ("" when all hold).
    """

    suspect: np.ndarray
    relabel: tuple[tuple[int, int], ...]
    reason: str


class SelfChecks:
    """The checks of one marker set's arms.

    Args:
        roles: the markers' landmarks.
        prior: the forearm rotation's range.
        min_flexion_deg: the elbow side is judged only with the elbow flexed this much.
        side_cos: ... and only when the epicondyle pair's direction is this near the flexion axis
            (cosine; a marker placed off its landmark tilts the pair).
        relabel_margin_deg: the exchanged reading must keep the forearm rotation's range by this much.
    """

    def __init__(self, roles: BodyRoles, prior: bm.BodyPrior = bm.BodyPrior(), *, min_flexion_deg: float = 30.0,
                 side_cos: float = 0.5, relabel_margin_deg: float = 20.0):
        self.roles = roles
        self.prior = prior
        self.min_flexion_deg = float(min_flexion_deg)
        self.side_cos = float(side_cos)
        self.relabel_margin_deg = float(relabel_margin_deg)

    def check(self, positions_m: np.ndarray, names: tuple[str, ...]) -> CheckResult:
        """Check the named positions ((M, 3) world metres, NaN where unknown)."""
        p = np.asarray(positions_m, dtype=np.float64)
        suspect = np.zeros(len(p), bool)
        relabel: list[tuple[int, int]] = []
        reasons: list[str] = []
        lo, hi = self.prior.forearm_rotation_deg
        for arm in self.roles.arms:
            s, e1, e2, w1, w2 = (p[k] for k in arm.markers)
            side = self._elbow_side(arm.sign, s, e1, e2, w1, w2)
            elbow = (arm.lateral_epicondyle, arm.medial_epicondyle)
            wrist = (arm.radial_styloid, arm.ulnar_styloid)
            if side < 0:
                relabel.append(elbow)
                reasons.append(f"{names[elbow[0]]} and {names[elbow[1]]} were exchanged (the elbow's side): named back")
                continue
            if not (np.isfinite(e1).all() and np.isfinite(e2).all() and np.isfinite(w1).all() and np.isfinite(w2).all()):
                continue
            with np.errstate(invalid="ignore", divide="ignore"):
                rot = float(bm.forearm_rotation_deg(arm.sign, e1, e2, w1, w2))
            if not np.isfinite(rot) or lo <= rot <= hi:
                continue
            turned = rot - 180.0 if rot > 90.0 else rot + 180.0
            if side > 0 and lo + self.relabel_margin_deg <= turned <= hi - self.relabel_margin_deg:
                relabel.append(wrist)
                reasons.append(f"{names[wrist[0]]} and {names[wrist[1]]} were exchanged (forearm rotation "
                               f"{rot:.0f} degrees): named back")
            else:
                doubt = wrist if side > 0 else elbow + wrist
                suspect[list(doubt)] = True
                reasons.append(f"{', '.join(names[k] for k in doubt)} suspect: the forearm rotation ({rot:.0f} "
                               f"degrees) is outside the forearm's range, angles that need them withheld")
        return CheckResult(suspect, tuple(relabel), "; ".join(reasons))

    def _elbow_side(self, sign: float, s: np.ndarray, e1: np.ndarray, e2: np.ndarray, w1: np.ndarray,
                    w2: np.ndarray) -> int:
        """+1: the lateral epicondyle marker on its side; -1: on the other; 0: cannot tell."""
        e, w = bm.mid(e1, e2), bm.mid(w1, w2)
        if not (np.isfinite(s).all() and np.isfinite(e1).all() and np.isfinite(e2).all() and np.isfinite(w).all()):
            return 0
        if float(bm.angle_deg(e - s, w - e)) < self.min_flexion_deg:
            return 0
        n = np.cross(s - e, w - e)
        c = float(np.dot(bm.unit(e1 - e2), bm.unit(n))) * -sign
        return 1 if c > self.side_cos else (-1 if c < -self.side_cos else 0)

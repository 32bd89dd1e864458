"""The body model's score of labelled positions: every term's value and its cost.

A labelling's score is the sum of the costs of the body model's terms (:mod:`.prior`) over its
markers' positions in the patient's frame: the trunk's, each arm's, the couplings of the arms to
the trunk, the shoulders' breadth, the arms' symmetry and their proportions to the shoulders.
The search (:mod:`.fit`, :mod:`.parts`, :mod:`.on_rays`) and the naming's checks of the rules'
labelling (:meth:`tracking.labelling.fit.Labeller.score_of`) score with it.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.labelling import prior as bm
from tracking.labelling.body_frame import patient_axes
from tracking.labelling.roles import BodyRoles


class BodyScore:
    """The body model's terms and costs of one marker set's roles.

    Args:
        roles: which marker is which landmark.
        prior: the body model's ranges (``table``: each term's range and scale, :func:`.prior.ranges`).
    """

    def __init__(self, roles: BodyRoles, prior: bm.BodyPrior):
        self.roles = roles
        self.prior = prior
        self.table = bm.ranges(prior)

    def terms_of(self, p_pat_m: np.ndarray) -> dict[str, float]:
        """Every term's value for labelled marker positions in the patient's frame ((M, 3), NaN unseen)."""
        return {k: float(v[0]) for k, v in self.terms(np.asarray(p_pat_m, dtype=np.float64)[None]).items()}

    def terms(self, p: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`terms_of` of a batch of labellings' positions ((N, M, 3)): name -> (N,) values."""
        r = self.roles
        out: dict[str, np.ndarray] = dict(bm.trunk_terms(self.prior, *(p[:, k] for k in r.trunk)))
        for arm in r.arms:
            s, e1, e2, w1, w2 = (p[:, k] for k in arm.markers)
            vals = {**bm.upper_arm_terms(self.prior, arm.sign, s, e1, e2),
                    **bm.forearm_terms(self.prior, arm.sign, s, e1, e2, w1, w2),
                    **bm.coupling_terms(self.prior, arm.sign, p[:, r.upper], p[:, r.lower],
                                        p[:, r.right_hip if arm.sign > 0 else r.left_hip], s,
                                        np.stack([e1, e2, w1, w2], axis=1))}
            out.update({f"{arm.side} {k}": v for k, v in vals.items()})
        a, b = (p[:, arm.shoulder] for arm in r.arms)
        out["shoulders"] = bm.norm(a - b)
        for name in bm.SYMMETRIC:
            out[f"symmetry {name}"] = np.abs(out[f"right {name}"] - out[f"left {name}"])
        for side in ("right", "left"):
            out[f"{side} upper_arm_ratio"] = out[f"{side} upper_arm"] / out["shoulders"]
            out[f"{side} reach_ratio"] = out[f"{side} reach"] / out["shoulders"]
        return out

    def scores(self, p: np.ndarray) -> np.ndarray:
        """(N,) the scores of a batch of labellings' positions ((N, M, 3), patient frame)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            total = np.zeros(len(p))
            for k, v in self.terms(p).items():
                key = "symmetry" if k.startswith("symmetry") else k.split(" ")[-1]
                total = total + bm.cost(v, *self.table[key])
            return total

    def cost_of(self, name: str, value: float) -> float:
        """The cost of a value of :meth:`terms_of`."""
        key = "symmetry" if name.startswith("symmetry") else name.split(" ")[-1]
        rng, scale = self.table[key]
        return float(bm.cost(np.float64(value), rng, scale))

    def score_of(self, p_world_m: np.ndarray, index: np.ndarray, yaw_deg: float = 0.0) -> float:
        """The body model's score of a given labelling (index -1: unseen) in the frame of ``yaw_deg``."""
        index = np.asarray(index)
        p = np.where((index >= 0)[:, None], np.asarray(p_world_m, dtype=np.float64)[np.maximum(index, 0)], np.nan)
        q = (p - np.nanmean(p, axis=0)) @ patient_axes(math.radians(yaw_deg))
        with np.errstate(invalid="ignore", divide="ignore"):
            terms = self.terms_of(q)
            return float(sum(self.cost_of(k, v) for k, v in terms.items() if np.isfinite(v)))

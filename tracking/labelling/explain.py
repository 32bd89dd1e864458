"""Telling the therapist why the markers cannot be named, in one line.

Point counts that do not fit the marker set name the colour and the body parts to check. When no
naming satisfies the rules, the search with the bar lowered below zero finds the one that breaks
them least, keeping the distance rules hard where possible (they hold in any pose, so the
near-naming then differs from the reference pose only by the pose); the worst-broken rule's
message is what the therapist is told. With one colour a pose that mirrors a valid one (palms
turned back: the two wrist markers swap places) cannot be told from it.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.labelling.body_frame import yaw_from_pairs
from tracking.labelling.constraints import Constraints
from tracking.labelling.search import MAX_REFINE, REFINE_TOL_DEG, RuleSearch
from tracking.markerset import MarkerSet

# relaxed bars for explaining a failure: the best near-assignment is looked for above each in turn
RELAXED_BARS_M = (-0.02, -0.05, -0.1, -0.15, -0.2, -0.3, -0.5, -math.inf)


class Explainer:
    """The one-line messages of a marker set's identification.

    Args:
        markerset: the marker set.
        words: the palette's colour words (:func:`tracking.labelling.words.palette_words`).
        search: the rules' search (its constraints' rules are explained).
    """

    def __init__(self, markerset: MarkerSet, words: list[str], search: RuleSearch):
        self.markerset = markerset
        self.words = words
        self.search = search
        self.constraints: Constraints = search.constraints
        self.rules = search.constraints.rules
        self.colour = search.constraints.colour

    def count_problem(self, colour: np.ndarray) -> str | None:
        """One line on the point counts per colour that do not fit the marker set, or None."""
        n_col = len(self.words)
        have = np.bincount(colour[(colour >= 0) & (colour < n_col)], minlength=n_col)
        want = np.bincount(self.colour, minlength=n_col)
        problems = []
        for k in np.flatnonzero(have != want):
            names = [n for n, c in zip(self.markerset.names, self.colour) if c == k]
            if have[k] < want[k]:
                missing = want[k] - have[k]
                which = "the hidden one" if missing == 1 else f"the {missing} hidden ones"
                problems.append(
                    f"{have[k]} of the {want[k]} {self.words[k]} markers are seen: {which} must be seen by two "
                    f"cameras (check that {self.where(names)} are not covered and the patient is in the reference pose)"
                )
            else:
                problems.append(
                    f"{have[k]} {self.words[k]} points are seen but there are {want[k]} {self.words[k]} markers "
                    f"({', '.join(names)}): remove or cover other {self.words[k]} objects in the cameras' view"
                )
        stray = int(np.sum((colour < 0) | (colour >= n_col)))
        if stray:
            problems.append(f"{stray} points have a colour that is not in the marker set's palette")
        return "; ".join(problems) if problems else None

    def where(self, names: list[str]) -> str:
        ms = self.markerset
        segs = list(dict.fromkeys(ms.segments[ms.index(n)].replace("_", " ") for n in names))
        listed = ", ".join(names)
        if len(segs) > 3:
            return f"the markers ({listed})"
        return f"the {' and '.join(segs)} markers ({listed})"

    def turned(self, yaw: float) -> str:
        deg = math.degrees(yaw)
        return (f"the patient sits turned {abs(deg):.0f} degrees to the {'left' if deg > 0 else 'right'} "
                f"(at most {self.rules.max_turn_deg:g} allowed): turn the chair to face the front")

    def explain(self, pts: np.ndarray, colour: np.ndarray, yaw: float) -> str:
        """One line: the worst-broken rule of the assignment that breaks the rules least.

        The distances between markers on one body part hold in any pose, so the assignment is
        first looked for among those that keep every distance rule: then only orderings fail and
        their message says how the pose differs. Only if no assignment keeps the distances (a
        marker misplaced, or a stray point taken for one) are all rules relaxed together. As in
        :meth:`tracking.labelling.rules.Identifier.identify`, the frame follows the near-assignment's own left-right pairs (a wrong
        pose can mislead the first guess from the spread of the points).
        """
        limit = math.radians(self.rules.max_turn_deg)
        near = None
        for _ in range(MAX_REFINE):
            for hard in (True, False):
                near = self.search.search(pts, colour, yaw, RELAXED_BARS_M, hard_distances=hard)
                if near is not None:
                    break
            if near is None:  # only with a spent node budget
                return f"the markers cannot be identified: {self.rules.reference_pose}"
            turn = yaw_from_pairs(pts, near.index[self.constraints.lr_pairs], yaw)
            if abs(turn) > limit:
                # a patient turned too far, or a wrong pose that mislabels a pair: the rules hold
                # in the turned frame only in the first case
                turned = self.search.settle(pts, colour, turn)
                if turned is not None:
                    return self.turned(yaw_from_pairs(pts, turned.index[self.constraints.lr_pairs], turn))
                break
            if abs(math.degrees(turn - yaw)) < REFINE_TOL_DEG:
                break
            yaw = turn
        margins = self.constraints.rule_margins(near.slack_m)
        broken = np.flatnonzero(margins < 0)
        worst = int(np.argmin(margins))
        rule = self.rules.rules[worst]
        more = f"{len(broken)} rules fail, worst " if len(broken) > 1 else "rule "
        return f"{rule.message} ({more}'{rule.text}' by {-margins[worst] * 1000:.0f} mm)"


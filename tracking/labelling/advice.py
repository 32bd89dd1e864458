"""The fit's one line for the therapist on a labelling that is not confident.

It names what keeps the fit from the reference pose: markers that fit it in more than one way,
or the body model's term furthest out of its range with what the patient does about it. The
marker set's ordering rules say it in their own words first (:mod:`.explain`; see the naming in
:mod:`tracking.pipeline.naming`).
"""

from __future__ import annotations

#: what the patient does about a term out of its range
ADVICE = {
    "abduction": "hold the {side} arm 5-40 degrees away from the body",
    "arm_flexion": "let the {side} arm hang at the side, neither forward nor back",
    "humeral_rotation": "let the {side} arm hang relaxed with the elbow crease forward or slightly inward",
    "elbow_flexion": "straighten the {side} elbow",
    "forearm_down": "let the {side} forearm hang down",
    "thumb": "turn the {side} hand so that the thumb points forward",
    "trunk_lean": "sit upright",
    "hips_tilt": "sit level on the chair",
    "hips_turn": "turn the chair to face the front",
}


def advice(lab, names: tuple[str, ...], table: dict[str, tuple[tuple[float, float], float]],
           max_score: float) -> str:
    """The line on ``lab`` (:class:`tracking.labelling.fit.Labelling`) for markers ``names``,
    with the body model's ranges ``table`` and the fit's ``max_score``."""
    if lab.index is None:
        return "the markers do not fit the reference pose"
    if lab.ambiguous and lab.score <= max_score:
        which = ", ".join(names[m] for m in lab.ambiguous)
        return (f"the markers {which} fit the reference pose in more than one way: hold the arms a little "
                "further from the body, elbows nearly straight, thumbs forward, and hold still")
    if lab.worst is not None:
        name, value = lab.worst
        side, _, term = name.rpartition(" ")
        rng, _ = table["symmetry" if side == "symmetry" else term]
        text = ADVICE.get(term, "")
        unit = "degrees" if term.endswith(("rotation", "abduction", "flexion", "axis", "thumb", "lean", "tilt",
                                          "turn", "down")) else "mm"
        shown = value if unit == "degrees" else 1000 * value
        lo, hi = (rng if unit == "degrees" else (1000 * rng[0], 1000 * rng[1]))
        where = f"{side} " if side and side != "symmetry" else ""
        return (f"the {where}{term.replace('_', ' ')} is {shown:.0f} {unit} (expected {lo:.0f} to {hi:.0f})"
                + (f": {text.format(side=side or 'either')}" if text else ""))
    return "the markers do not fit the reference pose"

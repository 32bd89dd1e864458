"""Labelling: which measured point is which marker, as the fit of a body model.

The 3D points of the reference pose are labelled by the labelling that best explains them under a
body model (:mod:`.prior`): segment lengths within population ranges, left/right structure, and
the reference pose as a prior with tolerances. Colours decide wherever they differ (a marker is
only ever given a point of its own colour). The search (:mod:`.fit`) scores every labelling that
could be within reach of the best and reports the best with a confidence: the margin to the
second best. A labelling is used only when it is confident. Its parts: :mod:`.body_score` the
body model's score of labelled positions, :mod:`.parts` the labellings within reach built arm by
arm and trunk and joined, :mod:`.on_rays` markers without a point placed on single-camera rays,
:mod:`.advice` the one line on a labelling that is not confident. The per-frame self-checks on the
named markers (:mod:`.checks`) use the pose-independent parts of the same model.

The body parts each marker stands for (:mod:`.roles`) come from the marker set's YAML. Where
the YAML names no roles, the marker set's ordering rules name the markers (:mod:`.rules`, with
:mod:`.constraints`, :mod:`.search`, :mod:`.ray_naming`, :mod:`.explain`); both use the
single-camera rays (:mod:`.rays`) and the patient's frame (:mod:`.body_frame`).
"""

from tracking.labelling.fit import Labeller, Labelling
from tracking.labelling.roles import BodyRoles

__all__ = ["BodyRoles", "Labeller", "Labelling"]

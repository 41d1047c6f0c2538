"""The synthetic 4D face world: template mesh, identities, action units, expressions,
sequences.

See ``book/01_face_world.ipynb`` for the equations and pictures.  Typical use::

    from facelib.face import Face, sample_identity, au_vector
    face = Face(sample_identity(7))
    vertices = face.expression(au_vector(AU25=1.0, AU26=0.8))   # (V, 3) in mm
    landmarks = face.landmarks(au_vector(AU12L=1, AU12R=1))      # (68, 3) in mm
"""

from .aus import AU_DESCRIPTIONS, AU_NAMES, NUM_AUS, Face, au_vector
from .expressions import (
    ALL_LABELS,
    BU_LABELS,
    COMA_LABELS,
    KIND_NAMES,
    RECIPES,
    check_label,
)
from .identity import IDENTITY_MODES, NUM_MODES, neutral_vertices, sample_identity
from .sequences import Timing, au_curves
from .template import Template, get_template

__all__ = [
    "AU_DESCRIPTIONS",
    "AU_NAMES",
    "NUM_AUS",
    "Face",
    "au_vector",
    "ALL_LABELS",
    "BU_LABELS",
    "COMA_LABELS",
    "KIND_NAMES",
    "RECIPES",
    "check_label",
    "IDENTITY_MODES",
    "NUM_MODES",
    "neutral_vertices",
    "sample_identity",
    "Timing",
    "au_curves",
    "Template",
    "get_template",
]

"""Expression labels as FACS recipes, with per-subject style (CoMA-like 12 and
BU-4DFE-like 6).

A recipe gives, for each action unit, the range of its apex intensity.  Some labels come
in
*variants* that a subject picks once and keeps (a subject lowers its brows for "eyebrow"
instead of raising them; "mouth_side" goes to the subject's habitual side).  On top of
that every subject has its own gain per AU (log-normal) and may leak a little of one
unrelated AU: this style is what makes subjects that were never seen hard to classify,
as in CoMA.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .aus import AU_NAMES, NUM_AUS

COMA_LABELS = (
    "bareteeth",
    "cheeks_in",
    "eyebrow",
    "high_smile",
    "lips_back",
    "lips_up",
    "mouth_down",
    "mouth_extreme",
    "mouth_middle",
    "mouth_open",
    "mouth_side",
    "mouth_up",
)
BU_LABELS = ("anger", "disgust", "fear", "happy", "sad", "surprise")
ALL_LABELS = COMA_LABELS + BU_LABELS
KIND_NAMES = ("N2E", "E2N")  # neutral -> expression, expression -> neutral


@dataclass(frozen=True)
class Recipe:
    """AU apex-intensity ranges of a label; ``variants`` are alternatives with
    probabilities."""

    aus: tuple  # ((AU name, low, high), ...)
    # ((probability, ((AU name, low, high), ...)), ...) replacing ``aus``
    variants: tuple = ()

    def variant_aus(self, index):
        return self.aus if index < 0 else self.variants[index][1]


def _r(**ranges):
    return tuple((name, lo, hi) for name, (lo, hi) in ranges.items())


RECIPES = {
    # CoMA-like: mouth-centred, several labels share AUs (lips_up / mouth_up /
    # mouth_middle).
    "bareteeth": Recipe(
        _r(AU10=(0.7, 1.0), AU20=(0.6, 0.9), AU25=(0.5, 0.8), AU26=(0.0, 0.15))
    ),
    "cheeks_in": Recipe(_r(AD35=(0.7, 1.0), AU18=(0.1, 0.4), AU23=(0.0, 0.3))),
    "eyebrow": Recipe(
        _r(AU1=(0.7, 1.0), AU2=(0.7, 1.0), AU5=(0.2, 0.6)),
        variants=((0.3, _r(AU4=(0.7, 1.0), AU7=(0.1, 0.4))),),
    ),
    # World 2 (issue 25): CoMA's subjects smile and open the mouth broadly, as its scans
    # show (world 1's recipes, AU12 0.8-1.0 and AU26 0.5-0.8, made a polite smile and a
    # half-open mouth).
    "high_smile": Recipe(
        _r(
            AU6=(0.7, 1.0),
            AU12L=(0.95, 1.2),
            AU12R=(0.95, 1.2),
            AU25=(0.3, 0.7),
            AU26=(0.0, 0.2),
        )
    ),
    "lips_back": Recipe(
        _r(AU20=(0.5, 0.8), AU23=(0.6, 1.0), AU12L=(0.1, 0.3), AU12R=(0.1, 0.3))
    ),
    "lips_up": Recipe(_r(AU10=(0.6, 1.0), AU17=(0.2, 0.5), AU18=(0.2, 0.5))),
    "mouth_down": Recipe(_r(AU15=(0.7, 1.0), AU17=(0.2, 0.5), AU26=(0.05, 0.25))),
    "mouth_extreme": Recipe(
        _r(AU25=(0.8, 1.0), AU26=(0.9, 1.3), AU20=(0.5, 0.9), AU2=(0.0, 0.5))
    ),
    "mouth_middle": Recipe(_r(AU18=(0.6, 1.0), AU23=(0.3, 0.7), AU17=(0.0, 0.3))),
    "mouth_open": Recipe(_r(AU25=(0.7, 1.0), AU26=(0.7, 1.0))),
    "mouth_side": Recipe(
        _r(AD30=(0.6, 1.0), AU12L=(0.5, 0.9)),
        variants=((0.5, _r(AD30=(-1.0, -0.6), AU12R=(0.5, 0.9))),),
    ),
    "mouth_up": Recipe(
        _r(AU17=(0.7, 1.0), AU10=(0.1, 0.4), AU23=(0.2, 0.5), AU15=(0.0, 0.3))
    ),
    # BU-4DFE-like: the six basic emotions (EMFACS-style prototypes).
    "anger": Recipe(
        _r(
            AU4=(0.7, 1.0),
            AU5=(0.2, 0.6),
            AU7=(0.4, 0.8),
            AU23=(0.5, 0.9),
            AU17=(0.0, 0.3),
        )
    ),
    "disgust": Recipe(
        _r(
            AU9=(0.7, 1.0),
            AU10=(0.5, 0.9),
            AU15=(0.2, 0.5),
            AU17=(0.1, 0.4),
            AU4=(0.0, 0.3),
        )
    ),
    "fear": Recipe(
        _r(
            AU1=(0.6, 0.9),
            AU2=(0.4, 0.8),
            AU4=(0.3, 0.6),
            AU5=(0.6, 1.0),
            AU20=(0.5, 0.9),
            AU25=(0.4, 0.8),
            AU26=(0.1, 0.3),
        )
    ),
    "happy": Recipe(
        _r(AU6=(0.6, 1.0), AU12L=(0.7, 1.0), AU12R=(0.7, 1.0), AU25=(0.0, 0.5))
    ),
    "sad": Recipe(_r(AU1=(0.6, 1.0), AU4=(0.4, 0.8), AU15=(0.6, 1.0), AU17=(0.2, 0.5))),
    "surprise": Recipe(
        _r(
            AU1=(0.7, 1.0),
            AU2=(0.7, 1.0),
            AU5=(0.5, 0.9),
            AU25=(0.6, 1.0),
            AU26=(0.5, 0.9),
        )
    ),
}
MAX_INTENSITY = 1.5  # the strongest any AU can be pushed (1 = a typical strong apex)
# never leaked: signed / blink / large jaw motion
LEAK_EXCLUDED = ("AD30", "AU45", "AU26")


@dataclass(frozen=True)
class StyleSpread:
    """How much subjects differ in performing a label (a dataset property, see
    config.DATASETS)."""

    gain_sigma: float = 0.25  # log-normal spread of a subject's gain per AU
    leak_probability: float = 0.5  # chance that a style leaks one unrelated AU...
    leak_max: float = 0.2  # ...with at most this intensity
    # a subject mixes up to this fraction of another label's recipe in
    blend_max: float = 0.0


def check_label(label):
    """Return a valid label name, or raise a ValueError naming the allowed labels."""
    if label not in RECIPES:
        raise ValueError(
            f"unknown expression label {label!r}; allowed: {', '.join(ALL_LABELS)}"
        )
    return label


@dataclass(frozen=True)
class Style:
    """A subject's way of performing one label: chosen variant, AU gains, leaked AU."""

    variant: int  # -1 = the main recipe
    gains: np.ndarray  # (NUM_AUS,)
    leak: np.ndarray  # (NUM_AUS,) intensities of leaked AUs
    # another label of the same set whose recipe is mixed in...
    blend_label: str | None = None
    blend: float = 0.0  # ...with this weight


def sample_style(label, rng, spread=StyleSpread(), labels=None):
    """Draw a subject's style for ``label`` from a numpy Generator.

    ``labels`` is the label set that ``blend_label`` is drawn from (default: the set of
    ``label``).
    """
    recipe = RECIPES[check_label(label)]
    variant = -1
    u = rng.random()
    for k, (p, _) in enumerate(recipe.variants):
        if u < p:
            variant = k
            break
        u -= p
    gains = np.exp(spread.gain_sigma * rng.standard_normal(NUM_AUS))
    # Left/right pairs share most of their gain: styles are only mildly asymmetric.
    left, right = AU_NAMES.index("AU12L"), AU_NAMES.index("AU12R")
    gains[right] = gains[left] * np.exp(0.3 * spread.gain_sigma * rng.standard_normal())
    leak = np.zeros(NUM_AUS)
    if rng.random() < spread.leak_probability:
        used = {name for name, _, _ in recipe.variant_aus(variant)}
        candidates = [a for a in AU_NAMES if a not in used and a not in LEAK_EXCLUDED]
        leak[AU_NAMES.index(candidates[rng.integers(len(candidates))])] = (
            rng.uniform(0.5, 1.0) * spread.leak_max
        )
    labels = labels or (COMA_LABELS if label in COMA_LABELS else BU_LABELS)
    others = [l for l in labels if l != label]
    blend_label = others[rng.integers(len(others))]
    blend = rng.uniform(0.0, spread.blend_max)
    return Style(variant, gains, leak, blend_label, blend)


def apex_intensities(label, style, rng, scale=1.0):
    """AU apex intensities (NUM_AUS,) of one performance of ``label`` in ``style``."""
    w = style.leak * rng.uniform(0.5, 1.0)
    for name, lo, hi in RECIPES[check_label(label)].variant_aus(style.variant):
        a = AU_NAMES.index(name)
        w[a] = rng.uniform(lo, hi) * style.gains[a] * scale
    if style.blend > 0:
        other = np.zeros(NUM_AUS)
        for name, lo, hi in RECIPES[style.blend_label].aus:
            other[AU_NAMES.index(name)] = (
                rng.uniform(lo, hi) * style.gains[AU_NAMES.index(name)] * scale
            )
        w = (1.0 - style.blend) * w + style.blend * other
    return np.clip(w, -MAX_INTENSITY, MAX_INTENSITY)

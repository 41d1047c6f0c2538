"""Every default of the book in one place: paper values, CPU-scaled values, fast-mode values.

Each value carries its source: the paper section, or "our choice" with the reason.
``FACELIB_FAST=1`` (set by ``make test``) selects the fast-mode values so that every notebook
executes in seconds; the default ("book") mode uses the full values.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
DATA_DIR = PROJECT_ROOT / "data"
SYNTHETIC_DIR = DATA_DIR / "synthetic"
CHECKPOINT_DIR = DATA_DIR / "checkpoints"


def fast_mode():
    """True when FACELIB_FAST is set to a true value (1/true/yes): small, quick runs for tests."""
    return os.environ.get("FACELIB_FAST", "").strip().lower() in ("1", "true", "yes", "on")


def cache_dir():
    """Where generated datasets are cached: $FACELIB_CACHE_DIR or data/synthetic/cache."""
    return Path(os.environ.get("FACELIB_CACHE_DIR", SYNTHETIC_DIR / "cache"))


@dataclass(frozen=True)
class DatasetSpec:
    """How a synthetic dataset is generated (see data/synthetic/README.md)."""

    name: str
    label_set: str  # "coma" or "bu": which expression labels
    num_subjects: int
    num_sequences: int
    num_test_subjects: int  # subjects held out for the "test" split
    takes_per_pair: int  # base number of sequences per (subject, label), N2E and E2N alternating
    seed: int
    style_gain_sigma: float  # how differently subjects perform a label (expressions.StyleSpread)
    style_leak_probability: float
    style_leak_max: float
    style_blend_max: float
    num_frames: int = 40  # paper §4: sequences of 40 frames


DATASETS = {
    # Paper §4: 689 CoMA sequences from 12 subjects performing 12 actions.  CoMA's labels are
    # instructions ("lips up") that subjects interpret freely: our choice of a wide style spread
    # makes them as hard to recognise on unseen subjects as the paper's GT row (83.8 %).  Our choice: 4 takes
    # per (subject, label) plus one extra take for 113 random pairs gives exactly 689; 3 subjects
    # (a quarter) are held out for testing.
    "coma": DatasetSpec("coma", "coma", num_subjects=12, num_sequences=689, num_test_subjects=3,
                        takes_per_pair=4, seed=1001, style_gain_sigma=0.45, style_leak_probability=0.9,
                        style_leak_max=0.4, style_blend_max=0.3),
    # Paper §4: 606 BU-4DFE recordings of 101 subjects x 6 emotions, each cut into an N2E and an
    # E2N sequence: 1212 sequences.  Our choice: 20 subjects held out for testing.
    "bu": DatasetSpec("bu", "bu", num_subjects=101, num_sequences=1212, num_test_subjects=20,
                      takes_per_pair=2, seed=2002, style_gain_sigma=0.25, style_leak_probability=0.5,
                      style_leak_max=0.2, style_blend_max=0.2),
}
SPLITS = ("train", "test", "all")

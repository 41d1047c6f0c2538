"""Temporal AU curves and 4D sequences (N2E / E2N), as in the paper's data (§4).

Time is normalised, tau = f / (F - 1) for frame f of F, so a sequence can be drawn at
any length with the same expression.  An N2E sequence rises from the neutral face to the
apex:

    w_a(tau) = apex_a * smoothstep((tau - onset_a) / duration_a)

with a sequence onset and duration and a small per-AU jitter of both (AUs do not start
together).  An E2N sequence is the mirror image: it starts at the apex and relaxes.
Blinks (AU45 pulses of ~0.1 time units) are sprinkled in, and the landmarks get i.i.d.
Gaussian capture noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .aus import AU_NAMES, NUM_AUS
from .template import smoothstep

MIN_FRAMES, MAX_FRAMES = 2, 400


@dataclass(frozen=True)
class Timing:
    """Ranges of the temporal parameters (normalised time units)."""

    onset: tuple = (0.02, 0.30)  # when the sequence starts to move
    duration: tuple = (0.35, 0.60)  # how long the rise (or the relaxation) lasts
    au_jitter: float = 0.04  # std of the per-AU onset offset
    duration_jitter: float = 0.15  # relative spread of the per-AU duration
    blink_rate: float = 0.6  # mean number of blinks per sequence
    blink_duration: float = 0.09
    noise_mm: float = 0.2  # std of the capture noise on the landmarks


def check_num_frames(num_frames):
    """Validate a sequence length and return it as an int."""
    if isinstance(num_frames, bool) or not isinstance(num_frames, (int, np.integer)):
        raise ValueError(
            f"num_frames must be an integer in [{MIN_FRAMES}, {MAX_FRAMES}], got"
            f" {num_frames!r}"
        )
    if not MIN_FRAMES <= num_frames <= MAX_FRAMES:
        raise ValueError(
            f"num_frames must be in [{MIN_FRAMES}, {MAX_FRAMES}], got {num_frames}"
        )
    return int(num_frames)


def au_curves(apex, kind, num_frames, rng, timing=Timing()):
    """AU intensity curves (F, NUM_AUS) for apex intensities (NUM_AUS,) and kind "N2E" /
    "E2N"."""
    num_frames = check_num_frames(num_frames)
    apex = np.asarray(apex, float)
    if apex.shape != (NUM_AUS,) or not np.all(np.isfinite(apex)):
        raise ValueError(
            f"apex must be a finite array of shape ({NUM_AUS},), got shape {apex.shape}"
        )
    if kind not in ("N2E", "E2N"):
        raise ValueError(f"kind must be 'N2E' or 'E2N', got {kind!r}")
    tau = np.linspace(0.0, 1.0, num_frames)[:, None]
    onset = rng.uniform(*timing.onset)
    duration = rng.uniform(*timing.duration)
    onsets = onset + timing.au_jitter * rng.standard_normal(NUM_AUS)
    durations = duration * np.exp(timing.duration_jitter * rng.standard_normal(NUM_AUS))
    rise = smoothstep((tau - onsets) / durations)  # (F, A)
    w = apex * (rise if kind == "N2E" else 1.0 - rise)
    # Blinks: short AU45 pulses added on top of whatever the eyes do.
    blink = np.zeros(num_frames)
    for _ in range(rng.poisson(timing.blink_rate)):
        centre = rng.uniform(0.05, 0.95)
        phase = (tau[:, 0] - centre) / timing.blink_duration
        blink += np.where(np.abs(phase) < 1, np.cos(0.5 * np.pi * phase) ** 2, 0.0)
    k = AU_NAMES.index("AU45")
    w[:, k] = np.clip(w[:, k] + blink, 0.0, 1.0)
    return w

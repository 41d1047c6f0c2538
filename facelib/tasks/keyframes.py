"""Landmark keyframes (not in the paper; the fine-control chapter): "put the left mouth
corner 8 mm higher at frame 25", and a natural sequence around it.  OmniControl and GMD
control chosen body joints at chosen frames; this is the same for the 68 facial
landmarks.

A keyframe constrains one landmark at one frame, to an absolute ``position`` (mm) or to
a ``displacement`` (mm) from the given neutral face.  With a neutral face the sequence
starts from it (frame 0 known, as geometry-adaptive generation's N2E order).  The
constrained coordinates are conditioned on like the known frames of expression filling
(Alg. 3 on coordinates instead of frames, "replace"), by reconstruction guidance on them
("reconstruction"), or both.

The constraints file of ``python -m facelib sample keyframes --constraints keys.json``::

    {"neutral": [[x, y, z], ... 68 rows] (optional, mm),
     "keys": [{"frame": 25, "landmark": 54, "displacement": [0, 8, 0]},
              {"frame": 10, "landmark": 8, "position": [0.5, -60.2, 12.0]}]}
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from ..config import (
    KEYFRAME_SPEED_RADIUS,
    KEYFRAME_TOLERANCE,
    NUM_FRAMES,
    NUM_LANDMARKS,
)
from ..guidance import ReconstructionGuidance
from ..inpainting import LANDMARK_LIMIT_MM, KnownFrames, landmark_array, neutral_faces
from .fill import known_noise
from .loading import denoiser_name, load_denoiser, task_settings
from .settings import Keyframes

KEY_FIELDS = ("frame", "landmark")
KEY_TARGETS = ("position", "displacement")


def check_keys(keys, num_frames=NUM_FRAMES, neutral=None):
    """The keys (a list of dicts, see the module docstring) as targets (F, 68, 3) in mm
    and their mask (F, 68); with a neutral face (68, 3), frame 0 is that face and
    displacements are taken from it.  A clear error for a missing field, a frame or
    landmark out of range, a key given twice or a displacement without a face.
    """
    if not isinstance(keys, (list, tuple)) or not keys:
        raise ValueError(
            "keys must be a non-empty list of {'frame', 'landmark', 'position' or"
            f" 'displacement'}}, got {keys!r}"
        )
    given, mask = np.zeros((num_frames, NUM_LANDMARKS, 3)), np.zeros(
        (num_frames, NUM_LANDMARKS), dtype=bool
    )
    if neutral is not None:
        given[0], mask[0] = neutral, True
    for key in keys:
        targets = [k for k in KEY_TARGETS if isinstance(key, dict) and k in key]
        if (
            not isinstance(key, dict)
            or any(k not in key for k in KEY_FIELDS)
            or len(targets) != 1
        ):
            raise ValueError(
                "a key needs 'frame', 'landmark' and one of 'position' or"
                f" 'displacement', got {key!r}"
            )
        frame, landmark = key["frame"], key["landmark"]
        try:
            value = landmark_array(key[targets[0]], f"key {key!r}: the {targets[0]}")
        except ValueError as e:
            raise ValueError(f"{e}; it must be 3 finite numbers (mm)") from None
        if (
            isinstance(frame, bool)
            or not isinstance(frame, int)
            or not 0 <= frame < num_frames
        ):
            raise ValueError(
                f"key {key!r}: the frame must be an integer in 0..{num_frames - 1}"
            )
        if (
            isinstance(landmark, bool)
            or not isinstance(landmark, int)
            or not 0 <= landmark < NUM_LANDMARKS
        ):
            raise ValueError(
                f"key {key!r}: the landmark must be an iBUG-68 index in 0..67"
            )
        if (
            value.shape != (3,)
            or not np.isfinite(value).all()
            or np.abs(value).max() > LANDMARK_LIMIT_MM
        ):
            raise ValueError(
                f"key {key!r}: the {targets[0]} must be 3 finite numbers (mm, within "
                f"+-{LANDMARK_LIMIT_MM:g})"
            )
        if mask[frame, landmark]:
            raise ValueError(
                f"landmark {landmark} at frame {frame} is constrained twice (or is the"
                " neutral face)"
            )
        if targets[0] == "displacement" and neutral is None:
            raise ValueError(
                f"key {key!r}: a displacement is taken from the neutral face: give one"
            )
        given[frame, landmark] = value + (
            neutral[landmark] if targets[0] == "displacement" else 0.0
        )
        mask[frame, landmark] = True
    return given, mask


def read_constraints(path):
    """(keys, neutral (68, 3) or None) from a constraints JSON file (schema in the
    module docstring)."""
    try:
        spec = json.loads(Path(path).read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path} is not valid JSON: {e}") from None
    except OSError as e:  # absent, a folder, unreadable
        raise ValueError(f"cannot read the constraints file {path}: {e}") from None
    if (
        not isinstance(spec, dict)
        or "keys" not in spec
        or set(spec) - {"keys", "neutral"}
    ):
        raise ValueError(
            f"{path}: expected an object with 'keys' (a list) and optionally 'neutral'"
            " (68 x 3)"
        )
    neutral = spec.get("neutral")
    return spec["keys"], None if neutral is None else check_neutral(neutral)


def check_neutral(neutral):
    """A neutral face's landmarks as a finite (68, 3) array (a clear error
    otherwise)."""
    return neutral_faces(neutral)


def keyframes(
    keys,
    n=4,
    neutral=None,
    settings=Keyframes(),
    denoiser=None,
    progress=True,
    **overrides,
):
    """n sequences (n, F, 68, 3) float32 in mm that meet landmark keyframes
    (:func:`check_keys`), generated around them by the unconditional DDPM.
    ``settings``: :class:`facelib.Keyframes` (the method)."""
    settings, shape = task_settings(settings, overrides, n)
    neutral = None if neutral is None else check_neutral(neutral)
    given, mask = check_keys(keys, shape[1], neutral)
    denoiser = denoiser or load_denoiser(
        denoiser_name(settings.dataset, settings.sampler, settings.steps)
    )
    diffusion = denoiser.chain_for(settings)
    x0 = denoiser.to_model(np.broadcast_to(given, shape))
    known = torch.as_tensor(np.broadcast_to(mask, shape[:3]).copy()).to(denoiser.device)
    guide = None
    if settings.method in ("reconstruction", "both"):
        guide = ReconstructionGuidance(
            denoiser.model, diffusion, x0, known, settings.reconstruction_scale
        )
    if settings.method in ("replace", "both"):
        guide = KnownFrames(
            diffusion,
            x0,
            known,
            known_noise(settings.seed),
            inner=guide,
            feather=settings.feather,
        )
        out = guide.sample(denoiser.model, settings.seed, progress=progress)
    else:
        out = diffusion.sample(
            denoiser.model, shape, seed=settings.seed, guide=guide, progress=progress
        )
    return denoiser.to_mm(out)


def key_errors(sequences, keys, neutral=None):
    """Distance (mm) of each keyed landmark from its target, (n, number of keys), for
    sequences (n, F, 68, 3)."""
    x = np.asarray(sequences, dtype=np.float64)
    given, mask = check_keys(
        keys, x.shape[1], None if neutral is None else check_neutral(neutral)
    )
    if neutral is not None:
        mask[0] = False  # the neutral frame is given, not a key
    frames, landmarks = np.nonzero(mask)
    return np.linalg.norm(x[:, frames, landmarks] - given[frames, landmarks], axis=-1)


def key_speeds(sequences, keys, radius=KEYFRAME_SPEED_RADIUS):
    """How fast each keyed landmark moves near its keyed frame f: the largest of its
    frame-to-frame speeds (mm/frame) over the pairs (g, g + 1) within ``radius`` frames
    of f (radius 1: into and out of f), (n, number of keys).  A key met by a jump shows
    here, also where the jump is moved a frame or two off the key.  Compare with
    :func:`real_speed_p95`."""
    x = np.asarray(sequences, dtype=np.float64)
    out = np.zeros((len(x), len(keys)))
    for j, key in enumerate(keys):
        f, l = key["frame"], key["landmark"]
        first, last = max(f - radius, 0), min(f + radius, x.shape[1] - 1)
        path = x[:, first : last + 1, l]
        out[:, j] = np.linalg.norm(np.diff(path, axis=1), axis=-1).max(axis=1)
    return out


def real_speed_p95(sequences, landmark):
    """The 95th percentile of a landmark's frame-to-frame motion (mm/frame) over real
    sequences (n, F, 68, 3)."""
    x = np.asarray(sequences, dtype=np.float64)[:, :, landmark]
    return float(np.percentile(np.linalg.norm(np.diff(x, axis=1), axis=-1), 95))


def keyframe_report(sequences, requests, real, tolerance=KEYFRAME_TOLERANCE):
    """How well sequences (n, F, 68, 3) meet n requests [(keys, neutral or None)], one
    sequence each: {"error": the largest key error of each (mm), "speed_ratio": the
    largest speed near a keyed frame (:func:`key_speeds`) over the 95th percentile of
    that landmark's speed in ``real`` sequences, "met": error within ``tolerance`` and
    no ratio above 1}, each an array (n,)."""
    x = np.asarray(sequences, dtype=np.float64)
    if len(x) != len(requests):
        raise ValueError(
            f"give one sequence per request ({len(requests)}), got {len(x)}"
        )
    p95 = {
        l: real_speed_p95(real, l)
        for l in {key["landmark"] for keys, _ in requests for key in keys}
    }
    error, ratio = np.zeros(len(x)), np.zeros(len(x))
    for k, (keys, neutral) in enumerate(requests):
        limits = [p95[key["landmark"]] for key in keys]
        error[k] = key_errors(x[k : k + 1], keys, neutral).max()
        ratio[k] = (key_speeds(x[k : k + 1], keys)[0] / limits).max()
    return {
        "error": error,
        "speed_ratio": ratio,
        "met": (error <= tolerance) & (ratio <= 1),
    }

"""The identity model: a neutral face per identity, from 14 smooth nonlinear modes.

An identity is a coefficient vector ``s`` in R^14, drawn from N(0, I).  Each mode either

* warps the canonical plane (x0, y0) -> (x, y) with a smooth, bounded field
  (``tanh(s_k)`` times a Gaussian-weighted displacement: eye spacing, jaw width, mouth
  width...), or
* scales the depth bumps of a facial feature by ``exp(c s_k)`` (nose, lips, chin...).

Depth is evaluated at the *canonical* coordinates and the vertices are then moved by the
warp, so every vertex (and so every landmark) stays on its feature: the topology never
changes. ``s = 0`` gives the template.
"""

from __future__ import annotations

import numpy as np

from . import template as tpl
from .template import bump, smoothstep

IDENTITY_MODES = (
    "face_width",
    "face_length",
    "jaw_width",
    "chin",
    "nose_length",
    "nose_width",
    "eye_spacing",
    "eye_size",
    "brow",
    "lip_fullness",
    "mouth_width",
    "cheek_fullness",
    "face_depth",
    "asymmetry",
)
NUM_MODES = len(IDENTITY_MODES)


def _as_coeffs(coeffs):
    s = np.asarray(coeffs, dtype=np.float64)
    if s.shape != (NUM_MODES,):
        raise ValueError(
            f"identity coefficients must have shape ({NUM_MODES},), got {s.shape}"
        )
    if not np.all(np.isfinite(s)):
        raise ValueError("identity coefficients contain NaN or inf")
    return s


def depth_gains(coeffs):
    """Per-feature depth gains (template.GAIN_GROUPS) of an identity: exp of its
    modes."""
    s = _as_coeffs(coeffs)
    m = dict(zip(IDENTITY_MODES, s))
    return {
        "forehead": np.exp(0.25 * m["face_depth"]),
        "brow_ridge": np.exp(0.30 * m["brow"]),
        "eye_socket": np.exp(0.18 * m["face_depth"] - 0.10 * m["eye_size"]),
        "eyeball": np.exp(0.12 * m["eye_size"]),
        "nose": np.exp(0.18 * m["nose_length"]),
        "nose_width_z": np.exp(0.20 * m["nose_width"]),
        "cheek": np.exp(0.35 * m["cheek_fullness"]),
        "lips": np.exp(0.30 * m["lip_fullness"]),
        "chin": np.exp(0.30 * m["chin"]),
        "profile": np.exp(0.30 * m["face_depth"]),
    }


def warp(canonical, coeffs):
    """Warp canonical (x0, y0) (..., 2) to the identity's (x, y) in mm
    (smooth, nonlinear in s)."""
    s = _as_coeffs(coeffs)
    m = {k: v for k, v in zip(IDENTITY_MODES, s)}
    th = {k: np.tanh(v) for k, v in m.items()}
    x, y = canonical[..., 0], canonical[..., 1]
    ax, sx = np.abs(x), np.sign(x)
    my = tpl.MOUTH_Y
    dx = (
        3.2 * th["eye_spacing"] * sx * bump(ax, y, 31.0, 31.0, 20.0, 14.0)
        + 0.16 * th["eye_size"] * (ax - 31.0) * sx * bump(ax, y, 31.0, 31.5, 16.0, 10.0)
        + 0.20 * th["nose_width"] * x * bump(x, y, 0.0, -8.0, 18.0, 12.0)
        + 0.16 * th["mouth_width"] * x * bump(x, y, 0.0, my, 30.0, 12.0)
        + 3.0 * th["cheek_fullness"] * sx * bump(ax, y, 52.0, -10.0, 20.0, 25.0)
        + 0.12 * th["jaw_width"] * x * smoothstep((-20.0 - y) / 50.0)
        + 1.6 * th["asymmetry"] * bump(x, y, 15.0, -30.0, 35.0, 30.0)
    )
    dy = (
        0.16 * th["eye_size"] * (y - 31.5) * bump(ax, y, 31.0, 31.5, 16.0, 10.0)
        + 2.8 * th["brow"] * bump(ax, y, 32.0, 48.0, 30.0, 8.0)
        - 3.5 * th["nose_length"] * bump(x, y, 0.0, -6.0, 16.0, 12.0)
        + 0.20 * th["lip_fullness"] * (y - my) * bump(x, y, 0.0, my, 28.0, 10.0)
        - 4.5 * th["chin"] * smoothstep((-60.0 - y) / 35.0)
        + 1.4 * th["asymmetry"] * x / 70.0 * smoothstep((y + 60.0) / 80.0)
    )
    length = 1.0 + (np.exp(0.06 * m["face_length"]) - 1.0) * smoothstep(
        (10.0 - y) / 40.0
    )
    width = np.exp(0.06 * m["face_width"])
    return np.stack([(x + dx) * width, (y + dy) * length], axis=-1)


def neutral_vertices(coeffs, template=None):
    """Neutral face mesh (V, 3) in mm of the identity with mode coefficients
    ``coeffs``."""
    t = template or tpl.get_template()
    s = _as_coeffs(coeffs)
    x0, y0 = t.canonical[:, 0], t.canonical[:, 1]
    z = tpl.depth(x0, y0, depth_gains(s)) * np.exp(
        0.05 * s[IDENTITY_MODES.index("face_depth")]
    )
    xy = warp(t.canonical, s)
    vertices = np.concatenate([xy, z[:, None]], axis=1)
    return tpl.place_mouth_band(vertices, t)


def sample_identity(seed):
    """Identity coefficients ~ N(0, I) from an integer seed or a numpy Generator."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    return rng.standard_normal(NUM_MODES)

"""FACS action units as identity-dependent displacement fields (after AU-Blendshape, Li
et al. 2025).

An expression of an identity with AU intensities ``w`` (one per AU) is

    M(w) = Jaw(w_26, w_30) o [ N + sum_a w_a B_a(s) + sum_(a,b) w_a w_b C_ab(s) ]

where N is the neutral mesh, B_a(s) the *stylized* blendshape of AU a for identity s,
C_ab a corrective field for the AU pairs that interact, and Jaw a rotation of the lower
face about the temporo-mandibular axis (AU26 jaw drop, with a small forward glide of the
condyles) and about the vertical axis (AD30 jaw sideways), each vertex rotated by its
jaw weight times the angle: nonlinear in w.

Identity dependence: every field is a sum of Gaussian regions in canonical coordinates,
each with a displacement vector.  For identity s, the amplitude is scaled by exp(0.3
tanh(a_a . s)), the vector is rotated by up to ~0.45 rad (tanh(d_a . s)), the region
centre moves by up to 3 mm (tanh(e_a . s)), and AU12 pulls the lip corner towards the
identity's own cheekbone.  The projections a_a, d_a, e_a are fixed random vectors of
this world (seed ``WORLD_SEED``).

World 2 (``Face(..., world=2)``, issue 25) keeps this skeleton and adds tissue mechanics
and calibrated magnitudes: see :mod:`facelib.face.tissue`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from .. import config
from . import template as tpl
from . import tissue
from .identity import NUM_MODES, depth_gains, neutral_vertices, _as_coeffs
from .template import MOUTH_Y, bump, smoothstep

# fixed constants of the synthetic world (projections of identity space)
WORLD_SEED = 4_2023

# The 20 action units.  AU26 and AD30 are rotations; AD30's intensity is signed (+ = to
# the subject's left), every other intensity is >= 0 (1 = a strong, typical apex).
AU_NAMES = (
    "AU1",
    "AU2",
    "AU4",
    "AU5",
    "AU6",
    "AU7",
    "AU9",
    "AU10",
    "AU12L",
    "AU12R",
    "AU15",
    "AU17",
    "AU18",
    "AU20",
    "AU23",
    "AU25",
    "AU26",
    "AD30",
    "AD35",
    "AU45",
)
AU_DESCRIPTIONS = {
    "AU1": "inner brow raiser",
    "AU2": "outer brow raiser",
    "AU4": "brow lowerer",
    "AU5": "upper lid raiser",
    "AU6": "cheek raiser",
    "AU7": "lid tightener",
    "AU9": "nose wrinkler",
    "AU10": "upper lip raiser",
    "AU12L": "lip corner puller (left)",
    "AU12R": "lip corner puller (right)",
    "AU15": "lip corner depressor",
    "AU17": "chin raiser",
    "AU18": "lip pucker",
    "AU20": "lip stretcher",
    "AU23": "lip tightener",
    "AU25": "lips part",
    "AU26": "jaw drop (rotation)",
    "AD30": "jaw sideways (rotation, signed)",
    "AD35": "cheek suck",
    "AU45": "blink",
}
NUM_AUS = len(AU_NAMES)
ROTATION_AUS = ("AU26", "AD30")
# temporo-mandibular axis, in front of the ears (mm)
JAW_PIVOT = np.array([0.0, -5.0, -85.0])
# the condyles slide forward as the jaw opens (mm at AU26 = 1; world 2: at
JAW_GLIDE = np.array([0.0, -2.0, 5.0])
#                                       the saturated opening, tissue.jaw_opening)
JAW_DROP_DEG = 9.0  # AU26 at intensity 1
JAW_SIDE_DEG = 6.0  # AD30 at intensity 1


@dataclass(frozen=True)
class Region:
    """A Gaussian region (in canonical |x0|, y0 for mirrored regions) with a
    displacement vector.

    ``d`` is (outward, up, forward) in mm: "outward" is +x on the subject's left and -x
    on the right for mirrored regions.  ``side`` is "both" (mirrored), "left", "right"
    or "mid". ``mask`` selects "upper" / "lower" (the two lips, split at the mouth line)
    or None. ``radial`` adds a displacement proportional to the offset from the region
    centre (mm per mm), used for pucker/tightening.
    """

    cx: float
    cy: float
    sx: float
    sy: float
    d: tuple
    side: str = "both"
    mask: str | None = None
    radial: tuple = (0.0, 0.0)


AU_REGIONS = {
    "AU1": [Region(15, 51, 12, 13, (0.4, 7.0, 0.8))],
    "AU2": [Region(44, 50, 14, 13, (0.6, 7.0, -0.4))],
    "AU4": [
        Region(21, 47, 13, 8, (-3.5, -4.0, 1.2)),
        Region(0, 44, 8, 7, (0, -1.5, 1.5), side="mid"),
    ],
    "AU5": [Region(31, 36.5, 12, 3.5, (0, 2.6, 0.6))],
    "AU6": [
        Region(38, 4, 15, 12, (0.6, 4.0, 2.2)),
        Region(31, 27.0, 12, 3.0, (0, 1.8, 0.4)),
    ],
    "AU7": [
        Region(31, 27.5, 12, 3.0, (0, 2.2, 0.3)),
        Region(31, 36.5, 12, 2.5, (0, -1.2, 0)),
    ],
    "AU9": [
        Region(9, 12, 7, 10, (0.6, 3.2, 0.6)),
        Region(16, 45, 10, 6, (-1.2, -2.2, 0)),
        Region(0, -31, 14, 5, (0, 1.8, 0.3), side="mid", mask="upper"),
    ],
    "AU10": [
        Region(9, -32, 14, 5, (0.3, 5.0, 1.5), mask="upper"),
        Region(18, -17, 8, 10, (0.6, 2.2, 0.6)),
    ],
    "AU12L": [
        Region(25, -38, 11, 9, (9.0, 6.0, -2.0), side="left"),
        Region(36, -18, 12, 12, (0.8, 2.2, 2.0), side="left"),
    ],
    "AU12R": [
        Region(25, -38, 11, 9, (9.0, 6.0, -2.0), side="right"),
        Region(36, -18, 12, 12, (0.8, 2.2, 2.0), side="right"),
    ],
    "AU15": [Region(25, -40, 10, 9, (0.8, -6.0, -0.6))],
    "AU17": [
        Region(0, -70, 17, 12, (0, 6.0, 4.0), side="mid"),
        Region(0, -43, 16, 5, (0, 4.0, 2.5), side="mid", mask="lower"),
    ],
    "AU18": [Region(0, MOUTH_Y, 26, 9, (0, 0, 7.0), side="mid", radial=(-0.40, -0.15))],
    "AU20": [Region(26, -39, 12, 10, (7.0, -1.2, -2.2))],
    "AU23": [
        Region(
            0, -33, 22, 5, (0, -2.4, -1.8), side="mid", mask="upper", radial=(-0.10, 0)
        ),
        Region(
            0, -44, 22, 5, (0, 2.4, -1.8), side="mid", mask="lower", radial=(-0.10, 0)
        ),
    ],
    "AU25": [
        Region(0, -34, 20, 6, (0, 2.2, 0), side="mid", mask="upper"),
        Region(0, -43, 20, 7, (0, -3.4, 0.3), side="mid", mask="lower"),
    ],
    "AD35": [
        Region(42, -28, 18, 15, (-4.5, 0, -8.0)),
        Region(0, MOUTH_Y, 24, 8, (0, 0, 2.5), side="mid", radial=(-0.15, 0)),
    ],
}
CORRECTIVES = {
    ("AU12L", "AU26"): [Region(25, -38, 10, 9, (1.0, 2.0, -1.5), side="left")],
    ("AU12R", "AU26"): [Region(25, -38, 10, 9, (1.0, 2.0, -1.5), side="right")],
    ("AU1", "AU4"): [Region(13, 49, 8, 6, (0, 2.5, 0.6))],
    ("AU6", "AU12L"): [Region(40, 0, 12, 10, (0, 1.5, 2.0), side="left")],
    ("AU6", "AU12R"): [Region(40, 0, 12, 10, (0, 1.5, 2.0), side="right")],
    ("AU18", "AU23"): [Region(0, MOUTH_Y, 18, 8, (0, 0, 2.5), side="mid")],
}


def mouth_split(x, y, soft=16.0):
    """Weight of the *upper* face at (x0, y0): a sharp step at the mouth line between
    the lip corners, a soft one (width ``soft`` mm) beyond them, so lips can part
    without tearing.
    """
    sharp = (y > MOUTH_Y).astype(float)
    smooth = smoothstep((y - MOUTH_Y) / soft + 0.5)
    outside = smoothstep((np.abs(x) - (tpl.MOUTH_CORNER_X - 2.0)) / 8.0)
    return (1.0 - outside) * sharp + outside * smooth


def jaw_weight(canonical):
    """How much each vertex follows the mandible (0..1), from canonical coordinates."""
    x, y = canonical[:, 0], canonical[:, 1]
    lower = 1.0 - mouth_split(x, y, soft=30.0)
    return lower * (
        1.0
        - 0.6 * smoothstep((np.abs(x) - 35.0) / 30.0) * smoothstep((y + 75.0) / 30.0)
    )


SELF_CORRECTIVES = tissue.self_correctives(Region)  # world 2 only
VOLUME_REGIONS = tissue.volume_regions(Region)  # world 2 only


def _world_projections():
    rng = np.random.default_rng(WORLD_SEED)
    names = (
        list(AU_NAMES)
        + [f"{a}+{b}" for a, b in CORRECTIVES]
        + [f"{a}+{b}" for a, b in SELF_CORRECTIVES]
    )
    proj = rng.standard_normal((len(names), 4, NUM_MODES)) / np.sqrt(NUM_MODES) * 1.3
    return dict(zip(names, proj))


_PROJECTIONS = _world_projections()


def _rotation(axis, angle):
    """Rotation matrices (..., 3, 3) about a unit axis by angles (...)."""
    k = np.asarray(axis, float)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = np.asarray(angle, float)[..., None, None]
    return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * (kx @ kx)


def _field(regions, canonical, neutral, normals, s, key, corner_target=None):
    """Displacement field (V, 3) of a list of regions for identity s (one AU at
    intensity 1)."""
    p_amp, p_rot, p_cx, p_cy = _PROJECTIONS[key] @ s
    amp = np.exp(0.3 * np.tanh(p_amp))
    phi = 0.45 * np.tanh(p_rot)
    shift = 3.0 * np.tanh(np.array([p_cx, p_cy]))
    x, y = canonical[:, 0], canonical[:, 1]
    out = np.zeros_like(neutral)
    for r in regions:
        sign = np.sign(x) + (x == 0)
        if r.side == "mid":
            w = bump(x, y, r.cx, r.cy + shift[1], r.sx, r.sy)
            out_dir = np.sign(x)
        else:
            w = bump(np.abs(x), y, r.cx + shift[0], r.cy + shift[1], r.sx, r.sy)
            out_dir = sign
            if r.side == "left":
                w = w * smoothstep(x / 8.0 + 0.5)
            elif r.side == "right":
                w = w * smoothstep(-x / 8.0 + 0.5)
        if r.mask == "upper":
            w = w * mouth_split(x, y)
        elif r.mask == "lower":
            w = w * (1.0 - mouth_split(x, y))
        d = np.stack(
            [out_dir * r.d[0], np.full_like(x, r.d[1]), np.full_like(x, r.d[2])], axis=1
        )
        if corner_target is not None and r is regions[0]:
            # AU12: pull towards the identity's own cheekbone, keeping the magnitude.
            side_target = corner_target * np.stack(
                [sign, np.ones_like(x), np.ones_like(x)], 1
            )
            direction = side_target - neutral
            direction /= np.maximum(
                np.linalg.norm(direction, axis=1, keepdims=True), 1e-6
            )
            d = direction * np.linalg.norm(r.d)
        d[:, 0] += r.radial[0] * (x - (0 if r.side == "mid" else sign * r.cx))
        d[:, 1] += r.radial[1] * (y - r.cy)
        # Rotate in the image plane, mirrored on the right side; a part follows the
        # surface normal.
        c, sn = np.cos(phi * out_dir), np.sin(phi * out_dir)
        d = np.stack(
            [c * d[:, 0] - sn * d[:, 1], sn * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1
        )
        d += 0.15 * np.tanh(p_rot) * np.linalg.norm(d, axis=1, keepdims=True) * normals
        out += amp * w[:, None] * d
    return out


def blink_field(canonical, neutral, s, meet=(0.25, 0.2)):
    """AU45: the upper lid slides down onto the lower lid; the eye opening collapses.

    The lids meet at a fraction ``meet[0] + meet[1] p`` of the opening above the lower
    lid, p in (-1, 1) depending on the identity (world 2: tissue.BLINK_MEET, lower, as
    measured).
    """
    x, y = canonical[:, 0], canonical[:, 1]
    upper, lower = tpl.eye_lids(x)
    inside_x = np.isfinite(upper)
    lower = np.where(inside_x, lower, tpl.EYE_CENTER[1] - 2.0)
    upper = np.where(inside_x, upper, tpl.EYE_CENTER[1] + 2.0)
    a = (np.abs(x) - tpl.EYE_CENTER[0]) / (tpl.EYE_HALF_WIDTH + 4.0)
    across = smoothstep((1.0 - np.abs(a)) / 0.35)
    # Fraction of the way down: 1 inside the opening, fading above the upper lid, 0
    # below the lower lid.
    frac = np.where(y > lower, 1.0, 0.0) * np.where(
        y > upper, 1.0 - smoothstep((y - upper) / 7.0), 1.0
    )
    # The lids meet at a fraction of the opening that depends on the identity (some
    # people close by dropping the upper lid only, others also raise the lower one).
    p = np.tanh(_PROJECTIONS["AU45"] @ s)
    meet = lower + (meet[0] + meet[1] * p[0]) * (upper - lower)
    down = -(np.minimum(y, upper) - meet) * frac * across
    up = (
        (meet - y)
        * np.clip((y - (lower - 4.0)) / 4.0, 0.0, 1.0)
        * (y <= lower)
        * across
    )
    out = np.zeros_like(neutral)
    out[:, 1] = down + up
    out[:, 2] = (0.8 + 0.5 * p[1]) * frac * across
    return out


def vertex_normals(vertices, faces):
    """Area-weighted unit vertex normals (V, 3)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


@dataclass
class Face:
    """One identity of the synthetic world: its neutral mesh, stylized AU basis and jaw.

    ``expression(w)`` evaluates M(w) for AU intensities ``w`` of shape (..., NUM_AUS);
    pass ``index`` (e.g. the landmark vertices) to evaluate only those vertices, which
    is much faster.
    """

    coeffs: np.ndarray
    template: tpl.Template = field(default_factory=tpl.get_template, repr=False)
    # 2: with facelib/face/tissue.py
    world: int = field(default=config.WORLD, repr=False)

    def __post_init__(self):
        self.coeffs = _as_coeffs(self.coeffs)
        if self.world not in config.WORLDS:
            raise ValueError(
                f"world must be one of {config.WORLDS}, got {self.world!r}"
            )

    @cached_property
    def neutral(self):
        """Neutral vertices (V, 3) in mm."""
        return neutral_vertices(self.coeffs, self.template)

    @cached_property
    def normals(self):
        """Unit vertex normals (V, 3) of the neutral mesh."""
        return vertex_normals(self.neutral, self.template.faces)

    @cached_property
    def basis(self):
        """Stylized blendshapes (NUM_AUS, V, 3) in mm at intensity 1 (zero for the
        rotations)."""
        t, s, normals = self.template, self.coeffs, self.normals
        # The target of AU12 on this identity's neutral (subject's left side): world 1
        # pulls to the cheekbone, world 2 to zygomaticus major's origin
        # (tissue.AU12_ORIGIN).
        cheek = self.neutral[
            _nearest(
                t.canonical, *((46.0, 10.0) if self.world == 1 else tissue.AU12_ORIGIN)
            )
        ]
        gains = depth_gains(s)
        fields = []
        for name in AU_NAMES:
            if name in ROTATION_AUS:
                fields.append(np.zeros_like(self.neutral))
            elif name == "AU45":
                fields.append(
                    blink_field(
                        t.canonical,
                        self.neutral,
                        s,
                        *(() if self.world == 1 else (tissue.BLINK_MEET,)),
                    )
                )
            else:
                target = (
                    np.array([abs(cheek[0]), cheek[1], cheek[2]])
                    if name.startswith("AU12")
                    else None
                )
                regions = AU_REGIONS[name]
                if self.world == 2:
                    g = tissue.AU_GAINS.get(name, 1.0)
                    regions = [
                        replace(
                            r,
                            d=tuple(g * c for c in r.d),
                            radial=tuple(g * c for c in r.radial),
                        )
                        for r in regions
                    ]
                    if target is not None:
                        regions[0] = replace(
                            regions[0],
                            d=tuple(
                                tissue.AU12_MM / np.linalg.norm(regions[0].d) * c
                                for c in regions[0].d
                            ),
                        )
                f = _field(regions, t.canonical, self.neutral, normals, s, name, target)
                if self.world == 2:
                    for group, region in VOLUME_REGIONS.get(name, ()):
                        f = f + gains[group] ** 2 * _field(
                            [region], t.canonical, self.neutral, normals, s, name
                        )
                fields.append(f)
        return np.stack(fields)

    @cached_property
    def correctives(self):
        """Corrective fields {(a, b): (V, 3)} of the interacting AU pairs."""
        t, s = self.template, self.coeffs
        pairs = CORRECTIVES if self.world == 1 else {**CORRECTIVES, **SELF_CORRECTIVES}
        return {
            pair: _field(
                regions,
                t.canonical,
                self.neutral,
                self.normals,
                s,
                f"{pair[0]}+{pair[1]}",
            )
            for pair, regions in pairs.items()
        }

    @cached_property
    def tissue_rig(self):
        """World 2's per-vertex tissue quantities: (curvature (V,), lip weight (V,), lip
        pivot (V, 3))."""
        return (
            tissue.curvature(self.neutral, self.template.faces, self.normals),
            *tissue.lip_rig(self.template.canonical, self.neutral),
        )

    @cached_property
    def jaw(self):
        """(per-vertex jaw weight (V,), pivot (3,), drop and sideways angles in rad at
        intensity 1).

        The pivot (temporo-mandibular axis) moves by up to 10 mm with the identity,
        which turns the direction in which the chin travels; the angles scale by
        exp(0.35 tanh(.)).
        """
        p = np.tanh(_PROJECTIONS["AU26"] @ self.coeffs)
        q = np.tanh(_PROJECTIONS["AD30"] @ self.coeffs)
        drop = np.deg2rad(
            JAW_DROP_DEG if self.world == 1 else tissue.JAW_DROP_DEG
        ) * np.exp(0.35 * p[0])
        side = np.deg2rad(JAW_SIDE_DEG) * np.exp(0.35 * q[0])
        pivot = JAW_PIVOT + np.array([0.0, 10.0 * p[1], 10.0 * p[2]])
        return jaw_weight(self.template.canonical), pivot, drop, side

    def expression(self, weights, index=None):
        """Vertices M(w) (..., V, 3) (or (..., len(index), 3)) for AU intensities (...,
        NUM_AUS)."""
        w = np.asarray(weights, dtype=np.float64)
        if w.shape[-1:] != (NUM_AUS,):
            raise ValueError(
                f"AU weights must have last dimension {NUM_AUS}"
                f" ({', '.join(AU_NAMES)}), got shape {w.shape}"
            )
        if not np.all(np.isfinite(w)):
            raise ValueError("AU weights contain NaN or inf")
        if index is None:
            return tpl.place_mouth_band(self._deform(w, slice(None)), self.template)
        index = np.asarray(index)
        in_band, lower, upper, fraction = tpl.mouth_band_sources(index)
        v = self._deform(w, index)
        if in_band.any():  # mouth-band vertices follow the inner lips of their column
            lips = self._deform(w, np.concatenate([lower, upper]))
            v[..., in_band, :] = tpl.mouth_band_positions(
                lips[..., : len(lower), :],
                lips[..., len(lower) :, :],
                fraction,
                self.template.canonical[index[in_band], 0],
            )
        return v

    def _deform(self, w, sel):
        """:meth:`_move`, then (world 2) lip contact: where the lower inner lip of a
        column ends up above the upper one, the two lips of that column are pushed apart
        by half the overlap each (tissue.lip_overlap, weighted by the lip rig), so that
        lips press instead of passing through.
        """
        v = self._move(w, sel)
        if self.world == 1:
            return v
        cols = tpl.N_COLS
        inner = np.concatenate(
            [
                tpl.LOWER_INNER_LIP_ROW * cols + np.arange(cols),
                tpl.UPPER_INNER_LIP_ROW * cols + np.arange(cols),
            ]
        )
        lips = self._move(w, inner)
        # (..., cols)
        overlap = tissue.lip_overlap(lips[..., :cols, 1], lips[..., cols:, 1])
        index = np.arange(len(self.neutral))[sel]
        v[..., 1] += 0.5 * self.tissue_rig[1][index] * overlap[..., index % cols]
        return v

    def _move(self, w, sel):
        """N + sum w B + sum w w C, then the jaw rotations, at vertices ``sel`` (no
        mouth band).

        World 2 stiffens and slides the summed displacement and rolls the lips before
        the jaw rotates, and its jaw saturates (facelib/face/tissue.py)."""
        d = np.einsum("...a,avc->...vc", w, self.basis[:, sel])
        if self.world == 1:
            # world 1 adds up in this order (its data are bit-identical to before)
            d = self.neutral[sel] + d
        for (a, b), c in self.correctives.items():
            ia, ib = AU_NAMES.index(a), AU_NAMES.index(b)
            d = d + (w[..., ia] * w[..., ib])[..., None, None] * c[sel]
        jaw_drop = w[..., AU_NAMES.index("AU26"), None]
        if self.world == 1:
            v = d
        else:
            kappa, lip_weight, lip_pivot = (q[sel] for q in self.tissue_rig)
            v = self.neutral[sel] + tissue.slide(
                tissue.stiffen(d), self.normals[sel], kappa
            )
            roll = np.deg2rad(tissue.LIP_ROLL_DEG) * (
                w[..., AU_NAMES.index("AU23")] - w[..., AU_NAMES.index("AU18")]
            )
            v = tissue.roll_lips(v, roll, lip_weight, lip_pivot)
            jaw_drop = tissue.jaw_opening(jaw_drop)
        jw, pivot, drop, side = self.jaw
        jw = jw[sel]
        drop_angle = drop * jaw_drop * jw  # (..., V)
        side_angle = side * w[..., AU_NAMES.index("AD30"), None] * jw
        rot = _rotation([0, 1, 0], side_angle) @ _rotation([1, 0, 0], drop_angle)
        return (
            np.einsum("...ij,...j->...i", rot, v - pivot)
            + pivot
            + (drop_angle / drop)[..., None] * JAW_GLIDE
        )

    def landmarks(self, weights):
        """The 68 landmarks (..., 68, 3) for AU intensities (..., NUM_AUS)."""
        return self.expression(weights, index=self.template.landmark_index)


def _nearest(canonical, x, y):
    return int(np.argmin((canonical[:, 0] - x) ** 2 + (canonical[:, 1] - y) ** 2))


def au_vector(**intensities):
    """AU intensity vector (NUM_AUS,) from keyword intensities, e.g. au_vector(AU25=1,
    AU26=0.8)."""
    w = np.zeros(NUM_AUS)
    for name, value in intensities.items():
        if name not in AU_NAMES:
            raise ValueError(
                f"unknown action unit {name!r}; allowed: {', '.join(AU_NAMES)}"
            )
        w[AU_NAMES.index(name)] = value
    return w

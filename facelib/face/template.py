"""The procedural template face: a grid surface shaped by analytic bumps (DESIGN.md,
"The synthetic face world").

The face is a height field over an oval.  A regular grid of ``N_ROWS x N_COLS`` vertices
is laid over canonical coordinates ``(x0, y0)`` in mm (x to the subject's left = image
right, y up, z towards the viewer).  Rows are denser around the eyes and the mouth, so
that lids and lips are resolved, and five rows between the inner lips form the mouth
interior (they are re-placed between the lips by :func:`place_mouth_band`, so the mouth
can open without tearing the mesh).

Every feature (nose, lips, brows...) is a smooth bump in the depth ``z(x0, y0)`` whose
amplitude is a *gain* that the identity model (``identity.py``) varies.  Features are
tied to grid vertices, so the 68 landmarks (``LANDMARK_INDEX``, iBUG-68 order) are fixed
vertices that follow their feature whatever the identity or expression.

Resolution levels keep every ``2**k``-th row and column of the grid (``N_ROWS = 9*8+1``
and ``N_COLS = 7*8+1`` make four levels), so pooling between levels is a sub-selection
and unpooling is bilinear interpolation along the grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.interpolate import PchipInterpolator

N_COLS = 57  # 7 * 8 + 1: columns, symmetric about x = 0 (column 28)
N_ROWS = 73  # 9 * 8 + 1: rows from the chin (row 0) to the top of the forehead
NUM_LEVELS = 4  # resolution levels: 4161, 1073, 285 and 80 vertices
MOUTH_BAND = 5  # rows of mouth interior between the inner lips

# Key rows and their height in mm (row index -> y0).  Rows in between are spaced by
# PCHIP. The rows LOWER_INNER_LIP_ROW < r < UPPER_INNER_LIP_ROW are the mouth band.
LOWER_INNER_LIP_ROW = 20
UPPER_INNER_LIP_ROW = LOWER_INNER_LIP_ROW + MOUTH_BAND + 1
_ROW_ANCHORS = {
    0: -106.0,
    6: -84.0,
    13: -52.0,
    LOWER_INNER_LIP_ROW: -39.6,
    UPPER_INNER_LIP_ROW: -36.9,
    33: -27.0,
    39: -12.0,
    49: 22.0,
    58: 40.0,
    63: 54.0,
    72: 100.0,
}
# Half width of the face (mm) as a function of height: an oval, widest at the
# cheekbones.
_HALF_WIDTH = (
    (-106, 22.0),
    (-95, 34.0),
    (-80, 46.0),
    (-55, 58.0),
    (-30, 67.0),
    (0, 72.0),
    (30, 73.0),
    (60, 67.0),
    (85, 58.0),
    (100, 50.0),
)

# Facial feature reference points of the template (mm), right side mirrored.
EYE_CENTER = (31.0, 31.5)  # subject's left eye; the right one is at x = -31
EYE_HALF_WIDTH = 14.5
EYE_UPPER, EYE_LOWER = 4.6, 3.4  # lid heights above / below the eye axis at its middle
IRIS_RADIUS, PUPIL_RADIUS = 5.3, 2.0
MOUTH_CORNER_X = 25.0
MOUTH_Y = -38.2
UPPER_LIP_TOP, LOWER_LIP_BOTTOM = -30.0, -47.0  # vermilion borders at the midline
BROW_Y = 47.5

SKIN = np.array([0.87, 0.69, 0.58])
LIP = np.array([0.72, 0.38, 0.38])
BROW = np.array([0.33, 0.23, 0.17])
SCLERA = np.array([0.95, 0.94, 0.90])
IRIS = np.array([0.30, 0.42, 0.52])
PUPIL = np.array([0.06, 0.05, 0.05])
MOUTH_INSIDE = np.array([0.30, 0.07, 0.08])
TEETH = np.array([0.93, 0.91, 0.84])


def smoothstep(a):
    """C1 step from 0 (a <= 0) to 1 (a >= 1)."""
    a = np.clip(a, 0.0, 1.0)
    return a * a * (3.0 - 2.0 * a)


def bump(x, y, cx, cy, sx, sy):
    """Unit Gaussian bump centred at (cx, cy) with widths (sx, sy) in mm."""
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


def half_width(y):
    """Half width of the template's oval outline at height y (mm)."""
    ys, ws = zip(*_HALF_WIDTH)
    return PchipInterpolator(ys, ws, extrapolate=True)(y)


def eye_lids(x):
    """Heights (upper, lower) of the subject's left eye contour at abscissa x (mm), NaN
    outside."""
    cx, cy = EYE_CENTER
    a = (np.abs(x) - cx) / EYE_HALF_WIDTH
    inside = np.abs(a) <= 1.0
    shape = np.where(inside, np.sqrt(np.clip(1.0 - a * a, 0.0, 1.0)), np.nan)
    tilt = 1.2 * a  # outer corner slightly higher (canthal tilt)
    upper = cy + tilt + EYE_UPPER * shape**0.8 * (1.0 - 0.15 * a)
    lower = cy + tilt - EYE_LOWER * shape**1.2
    return upper, lower


def lip_contours(x):
    """Heights (upper lip top, lower lip bottom) of the vermilion borders at abscissa x
    (mm)."""
    a = np.clip(np.abs(x) / (MOUTH_CORNER_X + 1.0), 0.0, 1.0)
    bow = 1.3 * np.exp(-(((np.abs(x) - 6.0) / 4.0) ** 2)) - 1.0 * np.exp(
        -((x / 2.5) ** 2)
    )
    upper = MOUTH_Y + (UPPER_LIP_TOP - MOUTH_Y) * (1.0 - a**2.2) + bow * (1.0 - a)
    lower = MOUTH_Y + (LOWER_LIP_BOTTOM - MOUTH_Y) * (1.0 - a**2.0)
    return upper, lower


# Depth features: name -> gain group.  ``depth`` multiplies each by its identity gain.
GAIN_GROUPS = (
    "forehead",
    "brow_ridge",
    "eye_socket",
    "eyeball",
    "nose",
    "nose_width_z",
    "cheek",
    "lips",
    "chin",
    "profile",
)


def depth(x, y, gains=None):
    """Depth z(x0, y0) in mm of the face surface with per-feature gains (default all
    1)."""
    g = {k: 1.0 for k in GAIN_GROUPS}
    if gains:
        g.update(gains)
    ax = np.abs(x)
    r = x / half_width(y)  # -1..1 across the oval
    # Base: a rounded head front that turns back at the sides, the forehead and under
    # the chin.
    z = 62.0 * (np.sqrt(np.clip(1.0 - 0.93 * r * r, 0.0, None)) - 1.0)
    z -= g["profile"] * (
        0.0028 * np.clip(y - 25.0, 0, None) ** 2
        + 0.0035 * np.clip(-60.0 - y, 0, None) ** 2
    )
    z += g["forehead"] * 6.0 * bump(x, y, 0.0, 72.0, 55.0, 30.0)
    z += g["brow_ridge"] * (
        5.5 * bump(ax, y, 28.0, 44.0, 24.0, 7.0) + 3.0 * bump(x, y, 0, 42, 10, 8)
    )
    # Eyes: a socket, the eyeball inside it and a crease above the upper lid.
    z -= g["eye_socket"] * 11.0 * bump(ax, y, 31.0, 33.0, 17.0, 11.0)
    z += g["eyeball"] * 7.0 * bump(ax, y, 31.0, 31.0, 11.0, 6.5)
    z -= 1.2 * bump(ax, y, 30.0, 39.5, 12.0, 1.6)
    # Nose: a ridge growing from the nasion to the tip, the tip bulb, the alae, the
    # nostril shadow.
    ridge_h = (
        21.0 * smoothstep((36.0 - y) / 40.0) * (1.0 - smoothstep((-2.0 - y) / 13.0))
    )
    ridge_w = 5.5 + 5.5 * smoothstep((30.0 - y) / 36.0)
    z += g["nose"] * ridge_h * np.exp(-((x / ridge_w) ** 2))
    z += g["nose"] * 4.0 * bump(x, y, 0.0, -4.0, 8.0, 6.5)
    z += g["nose_width_z"] * 7.5 * bump(ax, y, 13.5, -9.0, 6.5, 6.0)
    z -= 2.0 * bump(ax, y, 8.0, -14.5, 3.5, 2.0)
    # Cheeks, cheekbones, nasolabial folds.
    z += g["cheek"] * (
        7.0 * bump(ax, y, 42.0, -6.0, 17.0, 18.0)
        + 4.0 * bump(ax, y, 50.0, 14.0, 14.0, 9.0)
    )
    # a line from the ala down to the mouth corner
    fold = ax - (17.0 + 0.6 * (-8.0 - y))
    z -= 1.6 * np.exp(-((fold / 2.5) ** 2)) * bump(ax, y, 24.0, -24.0, 12.0, 12.0)
    # Lips, philtrum, the crease of the mouth line, the mentolabial sulcus, the chin.
    upper, lower = lip_contours(x)
    lip_span = smoothstep((MOUTH_CORNER_X + 3.0 - ax) / 6.0)
    z += (
        g["lips"]
        * lip_span
        * (
            6.5
            * smoothstep((y - MOUTH_Y) / 2.5)
            * smoothstep((upper + 1.5 - y) / 3.5)
            * (1.0 - 0.2 * ((y - MOUTH_Y) / (UPPER_LIP_TOP - MOUTH_Y)))
            + 7.0
            * smoothstep((MOUTH_Y - y) / 2.5)
            * smoothstep((y - lower + 1.5) / 4.5)
        )
    )
    z += 3.0 * bump(x, y, 0.0, -22.0, 16.0, 10.0)  # the upper-lip area sits forward
    z -= 0.9 * bump(x, y, 0.0, -23.0, 2.2, 5.0)  # philtrum
    z -= 3.5 * bump(x, y, 0.0, -53.5, 17.0, 3.8)
    z += g["chin"] * 9.0 * bump(x, y, 0.0, -72.0, 19.0, 13.0)
    return z


def _mix(col, target, weight):
    """Blend ``col`` towards ``target`` by ``weight`` (0..1, per vertex), in place."""
    col += weight[..., None] * (np.asarray(target) - col)


def albedo(x, y):
    """Per-vertex colour (RGB in 0..1) of the template: skin, brows, eyes, lips (soft
    edges)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    col = np.broadcast_to(SKIN, x.shape + (3,)).copy()
    ax = np.abs(x)
    # Brows: an arched band, thicker at the inner end.
    t = np.clip((ax - 12.0) / 44.0, 0.0, 1.0)
    brow_mid = BROW_Y + 4.0 * np.sin(np.pi * np.clip(t * 1.15, 0, 1)) - 2.5 * t
    thick = 3.2 - 1.8 * t
    along = smoothstep((ax - 10.5) / 3.0) * smoothstep((58.0 - ax) / 4.0)
    _mix(
        col, BROW, 0.9 * along * smoothstep((thick - np.abs(y - brow_mid)) / 1.6 + 0.5)
    )
    # Eyes: sclera between the lids, iris and pupil.
    upper, lower = eye_lids(x)
    opening = np.nan_to_num(np.minimum(upper - y, y - lower), nan=-9.0)
    in_eye = smoothstep(opening / 1.2 + 0.5)
    _mix(col, SCLERA, in_eye)
    d = np.hypot(ax - EYE_CENTER[0], y - EYE_CENTER[1] - 0.4)
    _mix(col, IRIS, in_eye * smoothstep((IRIS_RADIUS - d) / 1.2 + 0.5))
    _mix(col, PUPIL, in_eye * smoothstep((PUPIL_RADIUS - d) / 1.0 + 0.5))
    # Lips.
    up, lo = lip_contours(x)
    on_lip = smoothstep(np.minimum(up - y, y - lo) / 1.5 + 0.5) * smoothstep(
        (MOUTH_CORNER_X + 1.5 - ax) / 2.0
    )
    _mix(col, LIP, on_lip)
    return col


@dataclass(frozen=True)
class Level:
    """One resolution level: which template vertices it keeps and its triangles."""

    vertex_index: np.ndarray  # (V_k,) indices into the level-0 vertices
    faces: np.ndarray  # (K_k, 3) triangles indexing the level's own vertices
    shape: tuple  # (rows, cols) of the level's grid


def grid_faces(rows, cols):
    """Triangles of a rows x cols grid (row-major), facing +z, mirror-symmetric about
    the middle column."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = r * cols + c
    b, d, e = a + 1, a + cols, a + cols + 1
    left = (c < (cols - 1) // 2).ravel()  # the diagonal flips at the middle column
    a, b, d, e = a.ravel(), b.ravel(), d.ravel(), e.ravel()
    t1 = np.where(left[:, None], np.stack([a, b, e], 1), np.stack([a, b, d], 1))
    t2 = np.where(left[:, None], np.stack([a, e, d], 1), np.stack([b, e, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)


@dataclass(frozen=True)
class Template:
    """The template face: canonical coordinates, faces, colours, landmarks and
    resolution levels."""

    canonical: np.ndarray  # (V, 2) canonical (x0, y0) of every vertex, mm
    vertices: np.ndarray  # (V, 3) template vertices, mm
    faces: np.ndarray  # (K, 3)
    colors: np.ndarray  # (V, 3) RGB albedo
    landmark_index: np.ndarray  # (68,) vertex indices, iBUG-68 order
    # (68,) the landmark each one becomes in the left-right mirror image
    landmark_mirror: np.ndarray
    levels: tuple  # Level per resolution, level 0 = full mesh
    mouth_band: np.ndarray  # (MOUTH_BAND, C) vertex indices of the mouth interior rows

    @property
    def num_vertices(self):
        return len(self.vertices)

    def vertex(self, row, col):
        return row * N_COLS + col


def _row_heights():
    rows, ys = zip(*sorted(_ROW_ANCHORS.items()))
    return PchipInterpolator(rows, ys)(np.arange(N_ROWS))


def canonical_grid():
    """Canonical (x0, y0) of the grid vertices, shape (N_ROWS * N_COLS, 2),
    row-major."""
    y_rows = _row_heights()
    u = np.linspace(-1.0, 1.0, N_COLS)
    u = 0.72 * u + 0.28 * u**3  # denser columns in the middle of the face
    y = np.repeat(y_rows, N_COLS)
    x = np.tile(u, N_ROWS) * half_width(y)
    return np.stack([x, y], axis=1)


def _nearest_on_row(canonical, row, x):
    xs = canonical[row * N_COLS : (row + 1) * N_COLS, 0]
    return row * N_COLS + int(np.argmin(np.abs(xs - x)))


def _nearest_vertex(canonical, x, y):
    return int(np.argmin((canonical[:, 0] - x) ** 2 + (canonical[:, 1] - y) ** 2))


def _mirror(index):
    row, col = divmod(index, N_COLS)
    return row * N_COLS + (N_COLS - 1 - col)


def _landmarks(canonical):
    """The 68 landmark vertices in iBUG-68 order (jaw 17, brows 10, nose 9, eyes 12,
    mouth 20)."""
    idx = [None] * 68
    # Jaw line 0..16: from the right temple (image left) around the chin to the left
    # temple.
    ys = np.linspace(24.0, -95.0, 9)
    for k, y in enumerate(ys):  # k = 0 top (point 16) .. 8 chin (point 8)
        frac = 0.93 if k < 8 else 0.0
        x = frac * half_width(y) * (1.0 - 0.05 * k / 8)
        v = _nearest_vertex(canonical, x, y)
        idx[16 - k] = v
        idx[k] = _mirror(v)
    # Brows 17..21 (right, outer -> inner) and 22..26 (left, inner -> outer).
    for k, x in enumerate([14.0, 24.0, 34.0, 44.0, 53.0]):
        t = (x - 12.0) / 44.0
        y = BROW_Y + 4.0 * np.sin(np.pi * min(t * 1.15, 1.0)) - 2.5 * t
        v = _nearest_vertex(canonical, x, y)
        idx[22 + k] = v
        idx[21 - k] = _mirror(v)
    # Nose bridge 27..30 on the midline, lower nose 31..35.
    mid = N_COLS // 2  # the midline column, x0 = 0
    for k, y in enumerate([33.0, 21.0, 9.0, -3.0]):
        idx[27 + k] = _nearest_vertex(canonical, 0.0, y)
    for k, (x, y) in enumerate([(0.0, -14.5), (5.5, -13.5), (11.5, -11.5)]):
        idx[33 + k] = _nearest_vertex(canonical, x, y)
        idx[33 - k] = _mirror(idx[33 + k])
    # Eyes: 36..41 right eye (outer corner, 2 upper, inner corner, 2 lower); 42..47 left
    # eye (inner corner, 2 upper, outer corner, 2 lower).
    cx, cy = EYE_CENTER
    xs = np.array(
        [
            cx - EYE_HALF_WIDTH,
            cx - EYE_HALF_WIDTH / 3,
            cx + EYE_HALF_WIDTH / 3,
            cx + EYE_HALF_WIDTH,
        ]
    )
    up, lo = eye_lids(xs * 0.999)
    inner_c = _nearest_vertex(canonical, xs[0], cy - 1.2)
    outer_c = _nearest_vertex(canonical, xs[3], cy + 1.2)
    up1 = _nearest_vertex(canonical, xs[1], up[1])
    up2 = _nearest_vertex(canonical, xs[2], up[2])
    lo1 = _nearest_vertex(canonical, xs[1], lo[1])
    lo2 = _nearest_vertex(canonical, xs[2], lo[2])
    left_eye = [inner_c, up1, up2, outer_c, lo2, lo1]  # 42..47
    idx[42:48] = left_eye
    idx[36:42] = [_mirror(v) for v in [outer_c, up2, up1, inner_c, lo1, lo2]]
    # Mouth: outer lip 48..59, inner lip 60..67.
    xo = [MOUTH_CORNER_X, 15.0, 5.5, 0.0]
    uo, lo_ = lip_contours(np.array(xo) * 0.999)
    outer_corner = _nearest_on_row(
        canonical, LOWER_INNER_LIP_ROW + MOUTH_BAND // 2 + 1, MOUTH_CORNER_X + 1.5
    )
    idx[54] = outer_corner
    idx[48] = _mirror(outer_corner)
    idx[53], idx[52], idx[51] = (
        _nearest_vertex(canonical, x, y) for x, y in zip(xo[1:], uo[1:])
    )
    idx[49], idx[50] = _mirror(idx[53]), _mirror(idx[52])
    idx[55], idx[56], idx[57] = (
        _nearest_vertex(canonical, x, y) for x, y in zip(xo[1:], lo_[1:])
    )
    idx[59], idx[58] = _mirror(idx[55]), _mirror(idx[56])
    inner_corner = _nearest_on_row(
        canonical, LOWER_INNER_LIP_ROW + MOUTH_BAND // 2 + 1, MOUTH_CORNER_X - 3.0
    )
    idx[64] = inner_corner
    idx[60] = _mirror(inner_corner)
    ui = _nearest_on_row(canonical, UPPER_INNER_LIP_ROW, 10.0)
    li = _nearest_on_row(canonical, LOWER_INNER_LIP_ROW, 10.0)
    idx[63], idx[61] = ui, _mirror(ui)
    idx[62] = UPPER_INNER_LIP_ROW * N_COLS + mid
    idx[65], idx[67] = li, _mirror(li)
    idx[66] = LOWER_INNER_LIP_ROW * N_COLS + mid
    return np.array(idx, dtype=np.int64)


LANDMARK_REGIONS = {
    "jaw": range(0, 17),
    "brows": range(17, 27),
    "nose": range(27, 36),
    "eyes": range(36, 48),
    "mouth": range(48, 68),
}  # the iBUG-68 groups


def _landmark_mirror(landmark_index):
    """For each landmark i, the landmark j at the mirror vertex of i's (x0 -> -x0): a
    face mirrored left to right, x -> -x, has landmark j where the face had landmark i
    (iBUG-68: 0 <-> 16, 36 <-> 45, 48 <-> 54, ...).
    """
    where = {int(v): j for j, v in enumerate(landmark_index)}
    return np.array([where[_mirror(int(v))] for v in landmark_index], dtype=np.int64)


def _levels():
    levels = []
    rows, cols = np.arange(N_ROWS), np.arange(N_COLS)
    for k in range(NUM_LEVELS):
        step = 2**k
        r, c = rows[::step], cols[::step]
        index = (r[:, None] * N_COLS + c[None, :]).ravel()
        levels.append(Level(index, grid_faces(len(r), len(c)), (len(r), len(c))))
    return tuple(levels)


# depth of the mouth interior: mm at rest + mm per mm of lip gap
MOUTH_POCKET = (1.5, 0.45)


def mouth_band_sources(index):
    """For vertices ``index``: which are mouth-band vertices, and the two inner-lip
    vertices (lower, upper) of their column with their fraction between them.

    Returns (in_band (n,) bool, lower (m,), upper (m,), fraction (m,)) for the m band
    vertices.
    """
    row, col = np.divmod(np.asarray(index), N_COLS)
    in_band = (row > LOWER_INNER_LIP_ROW) & (row < UPPER_INNER_LIP_ROW)
    r, c = row[in_band], col[in_band]
    fraction = (r - LOWER_INNER_LIP_ROW) / (MOUTH_BAND + 1)
    return (
        in_band,
        LOWER_INNER_LIP_ROW * N_COLS + c,
        UPPER_INNER_LIP_ROW * N_COLS + c,
        fraction,
    )


def mouth_band_positions(lower, upper, fraction, x0):
    """Positions of band vertices between inner-lip vertices ``lower`` and ``upper``
    (..., m, 3).

    A band vertex sits at ``fraction`` of the way from the lower to the upper lip,
    pushed back (-z) in proportion to how far the lips are apart (between the mouth
    corners only, |x0| small), so that an opening mouth shows a cavity instead of a
    stretched membrane.
    """
    gap = np.linalg.norm(upper - lower, axis=-1, keepdims=True)
    inside = smoothstep((MOUTH_CORNER_X + 2.0 - np.abs(x0)) / 5.0)[:, None]
    pocket = (
        np.sin(np.pi * fraction)[:, None]
        * (MOUTH_POCKET[0] + MOUTH_POCKET[1] * gap)
        * inside
    )
    out = (1.0 - fraction[:, None]) * lower + fraction[:, None] * upper
    out[..., 2:3] -= pocket
    return out


def place_mouth_band(vertices, template):
    """Re-place the mouth-interior rows of full meshes (..., V, 3) between the inner
    lips, in place."""
    band = template.mouth_band.ravel()
    _, lower, upper, fraction = mouth_band_sources(band)
    vertices[..., band, :] = mouth_band_positions(
        vertices[..., lower, :],
        vertices[..., upper, :],
        fraction,
        template.canonical[band, 0],
    )
    return vertices


@lru_cache(maxsize=1)
def get_template():
    """Build (once) and return the template face."""
    canonical = canonical_grid()
    x, y = canonical[:, 0], canonical[:, 1]
    vertices = np.stack([x, y, depth(x, y)], axis=1)
    colors = albedo(x, y)
    band = np.array(
        [
            [(LOWER_INNER_LIP_ROW + k) * N_COLS + c for c in range(N_COLS)]
            for k in range(1, MOUTH_BAND + 1)
        ]
    )
    # Mouth interior colours: teeth near each lip, a dark cavity in between.
    xb = canonical[band[0], 0]
    inside = np.abs(xb) < MOUTH_CORNER_X - 1.0
    for k, c in enumerate([TEETH, MOUTH_INSIDE, MOUTH_INSIDE, MOUTH_INSIDE, TEETH]):
        colors[band[k][inside]] = c
    colors[band[:, ~inside].ravel()] = SKIN
    tpl = Template(
        canonical=canonical,
        vertices=vertices,
        faces=grid_faces(N_ROWS, N_COLS),
        colors=colors,
        landmark_index=(index := _landmarks(canonical)),
        landmark_mirror=_landmark_mirror(index),
        levels=_levels(),
        mouth_band=band,
    )
    place_mouth_band(tpl.vertices, tpl)
    for arr in (
        canonical,
        vertices,
        colors,
        tpl.landmark_index,
        tpl.landmark_mirror,
        band,
    ):
        arr.setflags(write=False)
    return tpl


def check_neutral_mesh(vertices):
    """A neutral mesh of the template topology as float32 (V, 3), or a clear error."""
    v = np.asarray(vertices)
    expected = get_template().num_vertices
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"a neutral mesh must be (V, 3) vertices, got shape {v.shape}")
    if v.shape[0] != expected:
        raise ValueError(
            f"the neutral mesh has {v.shape[0]} vertices; the template topology has"
            f" {expected} (meshes of another topology must first be registered to the"
            " template)"
        )
    if not np.all(np.isfinite(v)):
        raise ValueError(
            f"the neutral mesh has {int((~np.isfinite(v)).any(1).sum())} non-finite"
            " vertices"
        )
    return v.astype(np.float32)

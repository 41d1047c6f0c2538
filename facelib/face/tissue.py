"""World 2's tissue: what makes its action units act as real tissue does (issue 25).

World 1 adds displacement fields linearly, with a few pair correctives and the jaw's
rotation. World 2 keeps that skeleton, calibrates the magnitudes to published
measurements of real faces (``measures.PUBLISHED``) and adds, in the order they act on a
face with AU intensities w:

1. **Shapes that change with intensity**: a self-corrective w_a^2 C_aa per AU
   (``SELF_CORRECTIVES``).  A smile pulls the mouth corners out first, then up and back.
2. **Soft-tissue volume**: the bulges of the cheeks (AU6, AU12), the lips (AU18) and the
   chin (AU17) scale with the identity's own fullness there, g^2 with g its depth gain
   (``identity.depth_gains``), which the neutral mesh shows and landmarks do not.
3. **Strain stiffening**: skin stretches less the further it is pulled,
   d -> d / sqrt(1 + (|d| / L)^2) with L = ``STIFFENING_MM``.
4. **Skin sliding over the skull**: the tangential part d_t of the motion follows the
   identity's curved surface and falls back along the normal n by kappa |d_t|^2 / 2
   (kappa: the neutral mesh's curvature), d -> d - (kappa |d_t|^2 / 2) n.
5. **Lip rolling**: the red of each lip rotates about a pivot behind it, inwards when
   the lips tighten (AU23), outwards in a pucker (AU18): a rotation, nonlinear in w.
6. **Lip contact**: where a column's lower inner lip would end above its upper one, the
   lips press instead of passing through each other: each is pushed back by half the
   overlap (``lip_overlap``).
7. **A jaw that saturates**: the opening angle is theta * A tanh(w / A), A =
   ``JAW_RANGE``, about world 1's pivot, with world 2's larger ``JAW_DROP_DEG``; the
   condyles' forward glide (aus.JAW_GLIDE) follows the saturated opening.

Every step but the lip contact is local (a vertex needs only its own cached quantities);
the contact reads the two inner-lip rows, 114 vertices, so landmarks are still evaluated
without the full mesh.
"""

from __future__ import annotations

import numpy as np

from .template import MOUTH_CORNER_X, MOUTH_Y, smoothstep

# Calibration (measures.PUBLISHED): world 1's field of each AU is scaled by this gain.
AU_GAINS = {
    "AU1": 1.8,
    "AU2": 2.7,
    "AU4": 1.4,
    "AU9": 1.3,
    "AU10": 1.3,
    "AU15": 1.3,
    "AU17": 1.2,
    "AU18": 1.2,
    "AU20": 1.3,
    "AU25": 1.2,
}
# AU12 pulls the corner towards this point (canonical x0, y0): zygomaticus major's
# origin, seen from the front.  World 1 pulled towards the cheekbone (46, 10), too steep
# (65 deg against 47).
AU12_ORIGIN = (62.0, -14.0)
AU12_MM = 12.5  # |pull| of AU12 at intensity 1, before stiffening
# the lids meet this low in the opening (world 1: 0.25 +- 0.2)
BLINK_MEET = (0.08, 0.06)
JAW_DROP_DEG = 21.0  # AU26 at intensity 1, before saturation
JAW_RANGE = 1.2  # the jaw's angle saturates at JAW_RANGE * JAW_DROP_DEG
STIFFENING_MM = 30.0
# AU23 at intensity 1 rolls the lips in by this angle; AU18 rolls them out
LIP_ROLL_DEG = 25.0
# the pivot sits this far from the mouth line (mm) and this deep (mm)
LIP_PIVOT = (9.0, 7.0)
CONTACT_SOFTNESS = 0.5  # mm over which the lips' contact sets in (lip_overlap)
CURVATURE_LIMIT = 0.04  # 1/mm: |kappa| is clipped to this (a radius of 25 mm)...
# ...and smoothed by 30 rounds of neighbour averaging (about 17 mm: skull scale)
CURVATURE_SMOOTHING = 30


def self_correctives(region):
    """{(a, a): [Region]} of world 2: how each AU's shape changes with its intensity
    (w_a^2 C_aa)."""
    return {
        ("AU12L", "AU12L"): [region(25, -38, 10, 9, (-2.0, 2.5, -1.5), side="left")],
        ("AU12R", "AU12R"): [region(25, -38, 10, 9, (-2.0, 2.5, -1.5), side="right")],
        ("AU1", "AU1"): [region(15, 51, 10, 10, (0.0, -1.5, 0.4))],
        ("AU2", "AU2"): [region(44, 50, 12, 10, (0.0, -1.5, 0.0))],
        ("AU20", "AU20"): [region(26, -39, 10, 8, (-1.5, -1.0, -1.0))],
        ("AU10", "AU10"): [region(9, -32, 12, 5, (0.0, -1.0, 1.5), mask="upper")],
    }


def volume_regions(region):
    """{AU: [(depth-gain group, Region)]}: bulges whose size is the identity's fullness
    squared."""
    return {
        "AU6": [("cheek", region(40, -6, 14, 12, (0.5, 1.5, 4.0)))],
        "AU12L": [("cheek", region(38, -22, 12, 12, (0.8, 1.5, 3.0), side="left"))],
        "AU12R": [("cheek", region(38, -22, 12, 12, (0.8, 1.5, 3.0), side="right"))],
        "AU18": [("lips", region(0, MOUTH_Y, 22, 8, (0.0, 0.0, 4.0), side="mid"))],
        "AU17": [("chin", region(0, -68, 15, 10, (0.0, 2.0, 4.0), side="mid"))],
    }


def stiffen(d):
    """Strain stiffening of displacements (..., 3): d / sqrt(1 + (|d| / L)^2)."""
    norm2 = np.sum(d * d, axis=-1, keepdims=True)
    return d / np.sqrt(1.0 + norm2 / STIFFENING_MM**2)


def slide(d, normals, curvature):
    """Skin sliding over the surface: d - (kappa |d_t|^2 / 2) n, with d_t = d - (d . n)
    n."""
    dn = np.sum(d * normals, axis=-1, keepdims=True)
    dt2 = np.sum(d * d, axis=-1, keepdims=True) - dn**2
    return d - 0.5 * curvature[:, None] * dt2 * normals


def curvature(vertices, faces, normals):
    """Signed curvature (V,) in 1/mm of a mesh, positive where it is convex, at the
    scale of the skull: the umbrella operator kappa = 2 n . (v - mean of neighbours) /
    mean |v - neighbour|^2, clipped to CURVATURE_LIMIT, then smoothed over the mesh
    (CURVATURE_SMOOTHING rounds of neighbour averaging). ``normals``: the mesh's unit
    vertex normals (V, 3)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    count = np.bincount(edges.ravel(), minlength=len(vertices)).astype(float)
    total = np.zeros_like(vertices)
    np.add.at(total, edges[:, 0], vertices[edges[:, 1]])
    np.add.at(total, edges[:, 1], vertices[edges[:, 0]])
    sq = np.sum((vertices[edges[:, 0]] - vertices[edges[:, 1]]) ** 2, axis=1)
    mean_sq = (
        np.bincount(edges.ravel(), weights=np.repeat(sq, 2), minlength=len(vertices))
        / count
    )
    offset = vertices - total / count[:, None]
    kappa = np.clip(
        2.0 * np.sum(offset * normals, axis=1) / mean_sq,
        -CURVATURE_LIMIT,
        CURVATURE_LIMIT,
    )
    # the skull's curvature, not the lips' or the nose's detail
    for _ in range(CURVATURE_SMOOTHING):
        kappa = (
            0.5 * kappa
            + 0.5
            * (
                np.bincount(edges[:, 0], kappa[edges[:, 1]], len(kappa))
                + np.bincount(edges[:, 1], kappa[edges[:, 0]], len(kappa))
            )
            / count
        )
    return kappa


def lip_rig(canonical, neutral):
    """(weight (V,), pivot (V, 3)): how much each vertex rolls with its lip, and about
    which point.

    The red of the upper lip (within LIP_PIVOT[0] above the mouth line, inside the
    corners) rolls about a point LIP_PIVOT[0] above the mouth line and LIP_PIVOT[1]
    deep; the lower lip likewise below.  The pivot is placed in the face's own frame
    (the vertex's neutral height minus its canonical height above the mouth line is the
    face's mouth line there), so every lip vertex sits on the mouth's side of its pivot
    on every face.  The weight fades out towards the corners and away from the mouth
    line.
    """
    x, y = canonical[:, 0], canonical[:, 1]
    across = smoothstep((MOUTH_CORNER_X - np.abs(x)) / 8.0)
    dist = np.abs(y - MOUTH_Y)
    weight = across * smoothstep((LIP_PIVOT[0] - dist) / 4.0)
    sign = np.where(y >= MOUTH_Y, 1.0, -1.0)
    mouth_line = neutral[:, 1] - (y - MOUTH_Y)
    pivot = np.stack(
        [neutral[:, 0], mouth_line + sign * LIP_PIVOT[0], neutral[:, 2] - LIP_PIVOT[1]],
        axis=1,
    )
    return weight * sign, pivot


def roll_lips(v, angle, signed_weight, pivot):
    """Rotate lip vertices v (..., n, 3) about the x axis through ``pivot`` (n, 3) by
    ``angle`` (...,) times their signed weight (n,): positive angles roll both lips
    inwards.
    """
    a = angle[..., None] * signed_weight  # (..., n); the lower lip's sign is negative
    c, s = np.cos(a), np.sin(a)
    ry, rz = v[..., 1] - pivot[:, 1], v[..., 2] - pivot[:, 2]
    out = v.copy()
    out[..., 1] = pivot[:, 1] + c * ry - s * rz
    out[..., 2] = pivot[:, 2] + s * ry + c * rz
    return out


def lip_overlap(lower_y, upper_y, softness=CONTACT_SOFTNESS):
    """How far (mm) a lower inner lip at height ``lower_y`` has passed above the upper
    one at ``upper_y``: 0 while they are apart, the overlap d = lower_y - upper_y beyond
    ``softness``, and d^2 / (2 softness) in between (a smooth start of the contact)."""
    d = np.asarray(lower_y) - np.asarray(upper_y)
    return np.where(
        d <= 0, 0.0, np.where(d < softness, d * d / (2 * softness), d - softness / 2)
    )


def jaw_opening(w):
    """The saturating jaw: JAW_RANGE tanh(w / JAW_RANGE), the effective AU26 intensity
    (odd in w)."""
    return JAW_RANGE * np.tanh(np.asarray(w) / JAW_RANGE)

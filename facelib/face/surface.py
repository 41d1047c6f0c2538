"""The closest point of a triangle mesh to each of many points (registration and its
truth, the chapter "Your own face"): a k-d tree of triangle centroids proposes
candidates, Ericson's point-triangle test decides.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def closest_points(vertices, faces, points, candidates=16):
    """For each point (n, 3): the closest point of the triangle mesh (vertices, faces),
    as (triangle index (n,), barycentric coordinates (n, 3), distance (n,)).  The
    ``candidates`` triangles with the nearest centroids are searched exactly (Ericson,
    Real-Time Collision Detection, 5.1.5)."""
    v, f, p = np.asarray(vertices, float), np.asarray(faces), np.asarray(points, float)
    k = min(candidates, len(f))
    _, cand = cKDTree(v[f].mean(1)).query(p, k=k)
    cand = cand.reshape(len(p), k)
    a, b, c = (v[f[cand, i]] for i in range(3))
    bary = _closest_on_triangles(p[:, None], a, b, c)
    dist = np.linalg.norm(
        np.einsum("nkj,nkjd->nkd", bary, np.stack([a, b, c], 2)) - p[:, None], axis=-1
    )
    best = dist.argmin(1)
    rows = np.arange(len(p))
    return cand[rows, best], bary[rows, best], dist[rows, best]


def interpolate(values, faces, triangle, barycentric):
    """Per-vertex ``values`` (..., V, C) of a mesh with ``faces`` read at points given
    as (triangle (n,), barycentric (n, 3)), e.g. from :func:`closest_points`: (..., n,
    C)."""
    return np.einsum(
        "nk,...nkc->...nc",
        barycentric,
        np.asarray(values)[..., np.asarray(faces)[triangle], :],
    )


def _closest_on_triangles(p, a, b, c):
    """Barycentric coordinates (..., 3) of the point of triangle (a, b, c) closest to p
    (Ericson's regions)."""

    def dot(x, y):
        return (x * y).sum(-1)

    ab, ac = b - a, c - a
    d1, d2 = dot(ab, p - a), dot(ac, p - a)
    d3, d4 = dot(ab, p - b), dot(ac, p - b)
    d5, d6 = dot(ab, p - c), dot(ac, p - c)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        bary = np.stack([1 - v_in - w_in, v_in, w_in], -1)
        # Regions from the least to the most specific test of Ericson's order, so that
        # the first test wins.
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        regions = [
            (
                (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
                np.stack([0 * w, 1 - w, w], -1),
            )
        ]
        w = d2 / (d2 - d6)
        regions.append(
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([1 - w, 0 * w, w], -1))
        )
        regions.append(((d6 >= 0) & (d5 <= d6), np.array([0.0, 0.0, 1.0])))
        v = d1 / (d1 - d3)
        regions.append(
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([1 - v, v, 0 * v], -1))
        )
        regions.append(((d3 >= 0) & (d4 <= d3), np.array([0.0, 1.0, 0.0])))
        regions.append(((d1 <= 0) & (d2 <= 0), np.array([1.0, 0.0, 0.0])))
    for mask, value in regions:
        bary = np.where(mask[..., None], value, bary)
    # A degenerate triangle (zero area) that fell through every test: its first vertex.
    return np.where(
        np.isfinite(bary).all(-1, keepdims=True), bary, np.array([1.0, 0.0, 0.0])
    )

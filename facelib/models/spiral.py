"""Spiral convolution on the template's fixed topology (SpiralNet++, Gong et al. 2019; paper §3.3).

A mesh convolution needs an order of each vertex's neighbours that is the same for every vertex.
SpiralNet++ takes a *spiral*: the vertex itself, then its 1-ring, then its 2-ring, ..., each ring
walked in a fixed rotational direction, cut to a fixed length L.  Because every face of the book
shares the template's topology, the spirals are computed once, and a whole layer is

    gather (B, V, C) -> (B, V, L, C) -> reshape (B, V, L * C) -> one Linear -> (B, V, C_out).

Rings are ordered counter-clockwise by the angle around the vertex in the template's canonical
(x0, y0) plane, starting from +x; nearer vertices first at equal angle.  Near the border a ring is
a half-ring, and the spiral simply goes on into the next ring, so every spiral has length L.

Pooling between the template's resolution levels (face/template.py: every second grid row and
column) keeps the coarse level's vertices; unpooling interpolates the fine grid bilinearly.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch
from torch import nn

from ..face import template as tpl


def neighbours(faces, num_vertices):
    """The 1-ring of every vertex (list of sets) from triangles (K, 3)."""
    ring = [set() for _ in range(num_vertices)]
    for a, b, c in np.asarray(faces):
        ring[a] |= {b, c}
        ring[b] |= {a, c}
        ring[c] |= {a, b}
    return ring


def spiral_indices(faces, positions, length):
    """Spirals (V, length) int64 of a mesh: vertex, 1-ring, 2-ring, ... counter-clockwise in the
    (x, y) plane of ``positions`` (V, >= 2), cut to ``length``."""
    positions = np.asarray(positions, dtype=np.float64)[:, :2]
    v_count = len(positions)
    if length < 1:
        raise ValueError(f"spiral length must be positive, got {length}")
    ring_of = neighbours(faces, v_count)
    out = np.empty((v_count, length), dtype=np.int64)
    for v in range(v_count):
        spiral, seen, ring = [v], {v}, [v]
        while len(spiral) < length:
            nxt = sorted({u for w in ring for u in ring_of[w]} - seen)
            if not nxt:
                raise ValueError(f"vertex {v} reaches only {len(spiral)} vertices, fewer than the spiral length {length}")
            d = positions[nxt] - positions[v]
            angle = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
            ring = [nxt[i] for i in np.lexsort((np.hypot(d[:, 0], d[:, 1]), np.round(angle, 9)))]
            spiral += ring
            seen |= set(ring)
        out[v] = spiral[:length]
    return out


@lru_cache(maxsize=None)
def template_spirals(level, length):
    """Spirals (V_level, length) of a resolution level of the template (cached)."""
    t = tpl.get_template()
    lv = t.levels[level]
    return spiral_indices(lv.faces, t.canonical[lv.vertex_index], length)


class SpiralConv(nn.Module):
    """One spiral convolution: (B, V, in_channels) -> (B, V, out_channels)."""

    def __init__(self, in_channels, out_channels, indices):
        super().__init__()
        indices = torch.as_tensor(np.asarray(indices), dtype=torch.long)
        if indices.ndim != 2:
            raise ValueError(f"spiral indices must be (V, length), got {tuple(indices.shape)}")
        self.register_buffer("indices", indices, persistent=False)
        self.layer = nn.Linear(in_channels * indices.shape[1], out_channels)

    def forward(self, x):
        b, v, _ = x.shape
        if v != len(self.indices):
            raise ValueError(f"expected {len(self.indices)} vertices, got {v}")
        return self.layer(x[:, self.indices.reshape(-1)].reshape(b, v, -1))


@lru_cache(maxsize=None)
def pool_index(level):
    """Positions (V_{level+1},) of the coarser level's vertices among level ``level``'s vertices."""
    levels = tpl.get_template().levels
    where = {int(v): i for i, v in enumerate(levels[level].vertex_index)}
    return np.array([where[int(v)] for v in levels[level + 1].vertex_index], dtype=np.int64)


@lru_cache(maxsize=None)
def unpool_weights(level):
    """Bilinear interpolation from the coarser grid to level ``level``'s grid, as (V_level, 4) indices
    into the coarse vertices and (V_level, 4) weights: even rows/columns copy a coarse vertex, odd
    ones average their two (or four) coarse neighbours (unused slots have weight 0)."""
    levels = tpl.get_template().levels
    rows, cols = levels[level].shape
    coarse_cols = levels[level + 1].shape[1]
    index = np.zeros((rows * cols, 4), dtype=np.int64)
    weight = np.zeros((rows * cols, 4), dtype=np.float32)
    for r in range(rows):
        for c in range(cols):
            rs = [r // 2] if r % 2 == 0 else [r // 2, r // 2 + 1]
            cs = [c // 2] if c % 2 == 0 else [c // 2, c // 2 + 1]
            sources = [rr * coarse_cols + cc for rr in rs for cc in cs]
            index[r * cols + c, :len(sources)] = sources
            weight[r * cols + c, :len(sources)] = 1.0 / len(sources)
    return index, weight


def pool(x, level):
    """(B, V_level, C) -> (B, V_{level+1}, C): keep the coarser grid's vertices."""
    return x[:, torch.as_tensor(pool_index(level))]


def unpool(x, level):
    """(B, V_{level+1}, C) -> (B, V_level, C): bilinear interpolation on the grid (a gather of at
    most four coarse vertices per fine vertex, not a dense matrix product)."""
    index, weight = unpool_weights(level)
    gathered = x[:, torch.as_tensor(index).reshape(-1)].reshape(x.shape[0], len(index), 4, x.shape[2])
    return (gathered * torch.as_tensor(weight, dtype=x.dtype)[None, :, :, None]).sum(2)

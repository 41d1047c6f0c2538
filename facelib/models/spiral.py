"""Spiral convolution on the template's fixed topology (SpiralNet++, Gong et al. 2019;
paper §3.3).

A mesh convolution needs an order of each vertex's neighbours that is the same for every
vertex. SpiralNet++ takes a *spiral*: the vertex itself, then its 1-ring, then its
2-ring, ..., each ring walked in a fixed rotational direction, cut to a fixed length L.
Because every face of the book shares the template's topology, the spirals are computed
once, and a whole layer is

    gather (B, V, C) -> (B, V, L, C) -> reshape (B, V, L * C) -> one Linear -> (B, V,
    C_out).

Rings are ordered counter-clockwise by the angle around the vertex in the template's
canonical (x0, y0) plane, starting from +x; nearer vertices first at equal angle.  Near
the border a ring is a half-ring, and the spiral simply goes on into the next ring, so
every spiral has length L.

Pooling between the template's resolution levels (face/template.py: every second grid
row and column) keeps the coarse level's vertices; unpooling interpolates the fine grid
bilinearly.

Cost: a layer moves B x V x L x C numbers in its gather.  When a layer has fewer outputs
than inputs (the decoder), it projects first and gathers the projections (the same sum,
fewer numbers).
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
    """Spirals (V, length) int64 of a mesh: vertex, 1-ring, 2-ring, ...
    counter-clockwise in the (x, y) plane of ``positions`` (V, >= 2), cut to
    ``length``."""
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
                raise ValueError(
                    f"vertex {v} reaches only {len(spiral)} vertices, fewer than the"
                    f" spiral length {length}"
                )
            d = positions[nxt] - positions[v]
            angle = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
            ring = [
                nxt[i]
                for i in np.lexsort((np.hypot(d[:, 0], d[:, 1]), np.round(angle, 9)))
            ]
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
            raise ValueError(
                f"spiral indices must be (V, length), got {tuple(indices.shape)}"
            )
        self.register_buffer("indices", indices, persistent=False)
        self.layer = nn.Linear(in_channels * indices.shape[1], out_channels)

    def forward(self, x):
        b, v, c = x.shape
        if v != len(self.indices):
            raise ValueError(f"expected {len(self.indices)} vertices, got {v}")
        length, out = self.indices.shape[1], self.layer.out_features
        # index_select, not x[:, idx]: the same gather, whose backward (index_add) is
        # 1.6x faster on CPU.
        if out >= c:  # gather (B, V, L, C), reshape, one Linear
            return self.layer(
                torch.index_select(x, 1, self.indices.reshape(-1)).reshape(b, v, -1)
            )
        # Fewer outputs than inputs: the same sum,
        # W [x_s0; x_s1; ...] = sum_l W_l x_sl, computed as "project every vertex by
        # every W_l, then gather": it moves L * out numbers per vertex, not L * c.
        weight = self.layer.weight.reshape(out, length, c)
        projected = torch.einsum("bvc,olc->bvlo", x, weight).reshape(b, v * length, out)
        slot = self.indices * length + torch.arange(length, device=x.device)
        return (
            torch.index_select(projected, 1, slot.reshape(-1))
            .reshape(b, v, length, out)
            .sum(2)
            + self.layer.bias
        )


@lru_cache(maxsize=None)
def pool_index(level):
    """Positions (V_{level+1},) of the coarser level's vertices among level ``level``'s
    vertices."""
    levels = tpl.get_template().levels
    where = {int(v): i for i, v in enumerate(levels[level].vertex_index)}
    return np.array(
        [where[int(v)] for v in levels[level + 1].vertex_index], dtype=np.int64
    )


def pool(x, level):
    """(B, V_level, C) -> (B, V_{level+1}, C): keep the coarser grid's vertices.  (A
    network pools with :class:`Pool`, whose index is a buffer that moves with it; this
    copies the index to x's device.)
    """
    return torch.index_select(x, 1, torch.as_tensor(pool_index(level), device=x.device))


class Pool(nn.Module):
    """:func:`pool` as a module: the index of the kept vertices is a (non-persistent)
    buffer, so that ``module.to(device)`` moves it with the network."""

    def __init__(self, level):
        super().__init__()
        self.level = level
        self.num_fine = len(tpl.get_template().levels[level].vertex_index)
        self.register_buffer("index", torch.tensor(pool_index(level)), persistent=False)

    def forward(self, x):
        if x.shape[1] != self.num_fine:
            raise ValueError(
                f"expected {self.num_fine} vertices of level {self.level}, got"
                f" {x.shape[1]}"
            )
        return torch.index_select(x, 1, self.index)

    def extra_repr(self):
        return f"level={self.level}"


def unpool(x, level):
    """(B, V_{level+1}, C) -> (B, V_level, C): bilinear interpolation on the grid.  The
    coarse grid (r, c) sits at the fine grid's (2r, 2c), so this is ``interpolate(...,
    align_corners=True)`` to size (2R - 1, 2C - 1): even rows/columns copy a coarse
    vertex, odd ones average two or four (30 x faster on the CPU than gathering the four
    neighbours)."""
    levels = tpl.get_template().levels
    b, v, c = x.shape
    if v != len(levels[level + 1].vertex_index):
        raise ValueError(
            f"expected {len(levels[level + 1].vertex_index)} vertices of level"
            f" {level + 1}, got {v}"
        )
    grid = x.transpose(1, 2).reshape(b, c, *levels[level + 1].shape)
    fine = nn.functional.interpolate(
        grid, size=levels[level].shape, mode="bilinear", align_corners=True
    )
    return fine.reshape(b, c, -1).transpose(1, 2)

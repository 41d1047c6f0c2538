"""Spiral convolution (SpiralNet++) on the template: spirals, the layer, pooling between levels."""
import numpy as np
import pytest
import torch

from facelib.face import template as tpl
from facelib.models import spiral


def test_spirals_start_at_the_vertex_then_walk_rings_counter_clockwise():
    # a 5 x 5 grid: the centre's spiral is itself, its 1-ring (6 neighbours of a triangulated grid), then ring 2
    faces = tpl.grid_faces(5, 5)
    xy = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0), indexing="xy"), -1).reshape(-1, 2)
    s = spiral.spiral_indices(faces, xy, 12)
    centre = 12
    assert s[centre, 0] == centre
    ring1 = set(spiral.neighbours(faces, 25)[centre])
    assert set(s[centre, 1:1 + len(ring1)]) == ring1
    first = xy[s[centre, 1]] - xy[centre]
    assert first[1] == 0 and first[0] > 0  # starts along +x
    angles = np.mod(np.arctan2(*(xy[s[centre, 1:1 + len(ring1)]] - xy[centre]).T[::-1]), 2 * np.pi)
    assert np.all(np.diff(angles) > 0)  # counter-clockwise
    assert len(set(s[0])) == 12  # a corner vertex: half-rings, the spiral goes on into further rings


def test_template_spirals_are_consistent_and_valid():
    t = tpl.get_template()
    for level in range(tpl.NUM_LEVELS):
        s = spiral.template_spirals(level, 9)
        n = len(t.levels[level].vertex_index)
        assert s.shape == (n, 9) and s.min() >= 0 and s.max() < n
        assert np.array_equal(s[:, 0], np.arange(n))
        assert all(len(set(row)) == 9 for row in s)


def test_spiral_conv_is_gather_reshape_linear():
    s = spiral.template_spirals(3, 9)
    conv = spiral.SpiralConv(3, 5, s)
    x = torch.randn(2, len(s), 3)
    y = conv(x)
    assert y.shape == (2, len(s), 5)
    v = 17
    manual = conv.layer(x[:, s[v]].reshape(2, -1))
    torch.testing.assert_close(y[:, v], manual)
    with pytest.raises(ValueError, match="expected 80 vertices"):
        conv(torch.randn(2, 81, 3))


def test_spiral_conv_projects_before_gathering_when_it_narrows():
    # out < in takes the "project, then gather" path: it must be the same gather-reshape-Linear sum
    s = spiral.template_spirals(1, 9)
    conv = spiral.SpiralConv(16, 3, s)
    x = torch.randn(2, len(s), 16, dtype=torch.float64)
    conv = conv.double()
    manual = conv.layer(x[:, torch.as_tensor(s).reshape(-1)].reshape(2, len(s), -1))
    torch.testing.assert_close(conv(x), manual)


def test_pool_then_unpool_reproduces_linear_functions_on_the_grid():
    t = tpl.get_template()
    for level in range(tpl.NUM_LEVELS - 1):
        fine = t.canonical[t.levels[level].vertex_index]
        rows, cols = t.levels[level].shape
        grid = torch.as_tensor(np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), -1)
                               .reshape(-1, 2), dtype=torch.float64)[None]
        coarse = spiral.pool(grid, level)
        assert coarse.shape[1] == len(t.levels[level + 1].vertex_index)
        np.testing.assert_array_equal(t.levels[level].vertex_index[spiral.pool_index(level)],
                                      t.levels[level + 1].vertex_index)
        torch.testing.assert_close(spiral.unpool(coarse, level), grid)  # bilinear is exact on linear data
        assert len(fine) == rows * cols

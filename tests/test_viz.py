"""Renders, GIFs and landmark plots."""
import numpy as np
import pytest

from facelib import viz
from facelib.face import get_template


def test_render_face_draws_a_face():
    t = get_template()
    img = viz.render_face(t.vertices, size=(120, 150))
    assert img.shape == (150, 120, 3) and img.dtype == np.uint8
    face_pixels = (img < 250).any(axis=2)
    assert 0.2 < face_pixels.mean() < 0.9  # a face in the middle, background around it
    assert not face_pixels[:, 0].any() and not face_pixels[:, -1].any()


def test_renderer_updates_geometry_and_colours():
    t = get_template()
    r = viz.FaceRenderer(size=(100, 120))
    a = r.render(t.vertices, scalars=np.zeros(len(t.vertices)), clim=(0, 1))
    b = r.render(t.vertices * [1, 0.8, 1], scalars=np.ones(len(t.vertices)), clim=(0, 1))
    r.close()
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 1


def test_gif_html_and_landmark_plot_validate():
    frames = [np.full((10, 12, 3), k * 20, np.uint8) for k in range(3)]
    html = viz.gif_html(frames)
    assert html.startswith('<img src="data:image/gif;base64,')
    with pytest.raises(ValueError, match=r"landmarks must have shape \(68, 3\)"):
        viz.plot_landmarks(np.zeros((10, 3)))

import numpy as np

from facelib.face import template as tpl
from facelib.face.aus import vertex_normals


def test_template_shapes_and_topology():
    t = tpl.get_template()
    assert t.vertices.shape == (tpl.N_ROWS * tpl.N_COLS, 3)
    assert t.faces.shape[1] == 3 and t.faces.min() == 0 and t.faces.max() == len(t.vertices) - 1
    edges = {tuple(sorted(e)) for f in t.faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert len(t.vertices) - len(edges) + len(t.faces) == 1  # a disc
    assert 140 <= np.ptp(t.vertices[:, 0]) <= 160  # about 150 mm wide
    assert np.all(np.isfinite(t.vertices)) and t.colors.min() >= 0 and t.colors.max() <= 1


def test_triangles_face_the_viewer():
    t = tpl.get_template()
    tri = t.vertices[t.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(n, axis=1)
    front = n[:, 2] > 0
    assert (area[front].sum() / area.sum()) > 0.99


def test_landmarks_are_68_distinct_surface_vertices_in_ibug_layout():
    t = tpl.get_template()
    idx = t.landmark_index
    assert idx.shape == (68,) and len(set(idx.tolist())) == 68
    lm = t.vertices[idx]
    # jaw from the right (x < 0) to the left, chin at the bottom in the middle
    assert lm[0, 0] < 0 < lm[16, 0] and abs(lm[8, 0]) < 1e-9 and lm[8, 1] == lm[:, 1].min()
    assert lm[17:27, 1].min() > lm[36:48, 1].max()  # brows above eyes
    assert lm[36:48, 1].min() > lm[30, 1] > lm[48:68, 1].max()  # eyes above nose tip above mouth
    assert np.all(lm[61:64, 1] > lm[65:68, 1])  # upper inner lip above lower inner lip
    for i, j in ((0, 16), (36, 45), (39, 42), (48, 54), (60, 64), (31, 35), (17, 26)):
        np.testing.assert_allclose(lm[i] * [-1, 1, 1], lm[j], atol=1e-9)


def test_resolution_levels_are_nested_grids():
    t = tpl.get_template()
    sizes = [len(l.vertex_index) for l in t.levels]
    assert sizes == sorted(sizes, reverse=True) and sizes[0] == len(t.vertices)
    for fine, coarse in zip(t.levels, t.levels[1:]):
        assert set(coarse.vertex_index) <= set(fine.vertex_index)
        assert coarse.faces.max() == len(coarse.vertex_index) - 1


def test_mouth_band_lies_between_the_lips():
    t = tpl.get_template()
    lo = t.vertices[tpl.LOWER_INNER_LIP_ROW * tpl.N_COLS:(tpl.LOWER_INNER_LIP_ROW + 1) * tpl.N_COLS]
    up = t.vertices[tpl.UPPER_INNER_LIP_ROW * tpl.N_COLS:(tpl.UPPER_INNER_LIP_ROW + 1) * tpl.N_COLS]
    for k, row in enumerate(t.mouth_band, start=1):
        f = k / (tpl.MOUTH_BAND + 1)
        np.testing.assert_allclose(t.vertices[row][:, :2], ((1 - f) * lo + f * up)[:, :2], atol=1e-9)
        assert np.all(t.vertices[row][:, 2] <= ((1 - f) * lo + f * up)[:, 2] + 1e-9)  # pushed back


def test_vertex_normals_are_unit():
    t = tpl.get_template()
    n = vertex_normals(t.vertices, t.faces)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)


def test_the_landmark_mirror_is_an_involution_that_maps_the_template_onto_its_mirror_image():
    """iBUG-68's left-right pairs (jaw 0 <-> 16, eye corners 36 <-> 45, mouth corners 48 <-> 54, the midline
    fixed): the template, symmetric about x = 0, mirrored (x -> -x) has landmark mirror[i] where it had i."""
    t = tpl.get_template()
    m = t.landmark_mirror
    assert sorted(m) == list(range(68)) and (m[m] == np.arange(68)).all()
    assert (m[[0, 36, 48, 60, 17]] == [16, 45, 54, 64, 26]).all()
    assert (m[[8, 27, 30, 33, 51, 57, 62, 66]] == [8, 27, 30, 33, 51, 57, 62, 66]).all()
    landmarks = t.vertices[t.landmark_index]
    np.testing.assert_allclose(landmarks[m] * [-1, 1, 1], landmarks, atol=1e-6)

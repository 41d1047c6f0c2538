"""Registration of a reader's mesh (facelib/registration.py): closest points, similarity, units, bad input, and the
fit itself measured against a synthetic scan's truth (facelib/face/scans.py)."""
import json

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings, strategies as st
from scipy.spatial.transform import Rotation

from facelib import registration as reg
from facelib.__main__ import main as cli
from facelib.face import scans
from facelib.face.surface import _closest_on_triangles, closest_points
from facelib.face.template import get_template

T = get_template()


def test_closest_points_match_a_brute_force_search():
    rng = np.random.default_rng(0)
    mesh = trimesh.creation.icosphere(2, radius=10.0)
    v = mesh.vertices + rng.normal(0, 0.5, mesh.vertices.shape)
    points = rng.normal(0, 12.0, (300, 3))
    tri, bary, dist = closest_points(v, mesh.faces, points, candidates=len(mesh.faces))
    a, b, c = (v[mesh.faces[:, i]][None] for i in range(3))
    all_bary = _closest_on_triangles(points[:, None], a, b, c)  # every point against every triangle
    all_points = np.einsum("nkj,nkjd->nkd", all_bary, np.stack([a, b, c], 2).repeat(len(points), 0))
    brute = np.linalg.norm(all_points - points[:, None], axis=-1).min(1)
    np.testing.assert_allclose(dist, brute, atol=1e-9)
    assert (bary >= -1e-12).all() and np.allclose(bary.sum(1), 1.0)
    np.testing.assert_allclose(np.einsum("nk,nkd->nd", bary, v[mesh.faces[tri]]) - points,
                               np.zeros_like(points), atol=dist.max() + 1e-9)
    # The default candidates (16 nearest centroids) find the same points on this mesh.
    assert np.allclose(closest_points(v, mesh.faces, points)[2], brute)


def test_closest_point_regions_of_one_triangle():
    a, b, c = np.eye(3)[0] * 0, np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    cases = {(0.2, 0.2, 1.0): (0.6, 0.2, 0.2), (-1, -1, 0): (1, 0, 0), (2, -1, 0): (0, 1, 0), (-1, 2, 0): (0, 0, 1),
             (0.5, -1, 0): (0.5, 0.5, 0), (-1, 0.5, 0): (0.5, 0, 0.5), (1, 1, 0): (0, 0.5, 0.5)}
    for p, expected in cases.items():
        np.testing.assert_allclose(_closest_on_triangles(np.array(p, float), a, b, c), expected, atol=1e-12)


def test_similarity_recovers_a_known_transform():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, 3))
    r = Rotation.from_euler("xyz", [30, -70, 120], degrees=True).as_matrix()
    s, rot, t = reg.similarity(x, 2.5 * x @ r.T + [1.0, 2.0, 3.0])
    assert s == pytest.approx(2.5) and np.allclose(rot, r) and np.allclose(t, [1, 2, 3])


@pytest.mark.parametrize("extent, units", [(150.0, "mm"), (15.0, "cm"), (0.15, "m")])
def test_units_are_detected_from_the_size_and_checked(extent, units):
    assert reg.detect_units(extent) == units
    assert reg.detect_units(extent, units) == units
    other = "m" if units != "m" else "mm"
    with pytest.raises(ValueError, match=f"--units {other} contradicts its size; it looks like {units}"):
        reg.detect_units(extent, other)


def test_bad_meshes_are_refused_with_what_is_allowed(tmp_path):
    face = T.vertices * 1.0
    with pytest.raises(ValueError, match="no triangles: a point cloud cannot be registered"):
        reg.check_mesh(face, np.zeros((0, 3), int))
    with pytest.raises(ValueError, match="no vertices"):
        reg.check_mesh(np.zeros((0, 3)), T.faces)
    bad = face.copy()
    bad[7] = np.nan
    with pytest.raises(ValueError, match="1 vertex with NaN or inf"):
        reg.check_mesh(bad, T.faces)
    with pytest.raises(ValueError, match="index vertices outside"):
        reg.check_mesh(face, T.faces + 5000)
    with pytest.raises(ValueError, match="allowed: 300 to 200,000"):
        reg.check_mesh(face[:100], T.faces[(T.faces < 100).all(1)])
    with pytest.raises(ValueError, match="a face mesh is 80-500 mm across"):
        reg.check_mesh(face * 100, T.faces)
    with pytest.raises(ValueError, match="does not exist"):
        reg.read_mesh(tmp_path / "missing.obj")
    (tmp_path / "face.xyz").write_text("0 0 0\n")
    with pytest.raises(ValueError, match="unknown mesh format '.xyz'"):
        reg.read_mesh(tmp_path / "face.xyz")
    (tmp_path / "garbage.ply").write_bytes(b"ply\nformat nonsense\n\x00\x01")
    with pytest.raises(ValueError, match="cannot read|no vertices|no triangles"):
        reg.read_mesh(tmp_path / "garbage.ply")
    trimesh.PointCloud(face).export(tmp_path / "cloud.ply")
    with pytest.raises(ValueError, match="point cloud"):
        reg.read_mesh(tmp_path / "cloud.ply")
    with pytest.raises(ValueError, match="units must be one of"):
        reg.Registration(units="inch")


@pytest.fixture(scope="module")
def scan_fit():
    """A decimated (about 2k vertices), randomly rotated face in cm with eyeballs, registered."""
    scan = scans.make_scan(4545, remeshing="decimated", units="cm", extra=True)
    mesh = reg.check_mesh(scan.vertices, scan.faces)
    return scan, reg.register(mesh)


def test_registration_finds_the_landmarks_of_an_unseen_decimated_face(scan_fit):
    scan, fit = scan_fit
    assert fit.mesh.units == "cm"
    error_mm = np.linalg.norm(fit.landmarks - scan.truth_landmarks, axis=1) * 10
    # The targets (remeshed faces of unseen identities): median <= 1.5 mm, 95th percentile <= 3 mm.
    assert np.median(error_mm) <= 1.5 and np.percentile(error_mm, 95) <= 3.0, error_mm
    assert fit.residual_mm["all"] < 0.5
    # The canonical pose: the fitted template sits where the template does.
    assert np.abs(fit.neutral - T.vertices).mean() < 10.0


def test_transfer_keeps_frame_0_and_carries_the_true_motion(scan_fit):
    scan, fit = scan_fit
    r, _ = fit.pose
    for label in ("high_smile", "mouth_open"):
        frames = np.stack([fit.neutral, fit.neutral + (scan.template_motion[label] * 10) @ r.T])
        out = fit.transfer(frames)
        assert out.shape == (2, len(scan.vertices), 3)
        np.testing.assert_array_equal(out[0], scan.vertices)  # frame 0 is the user's mesh, exactly
        error = np.linalg.norm(out[1] - scan.vertices - scan.truth_motion[label], axis=1)[scan.face_vertex] * 10
        assert error.mean() <= 1.0, (label, error.mean())  # the apex target
    with pytest.raises(ValueError, match="template meshes"):
        fit.transfer(np.zeros((2, 10, 3)))


@pytest.mark.parametrize("name", ["sphere", "plane"])
def test_a_mesh_that_is_not_a_face_is_refused_with_its_residual(name):
    v, f = scans.not_faces()[name]
    with pytest.raises(reg.NotAFaceError, match=r"does not look like a face: .* residual of \d+\.\d\d mm") as e:
        reg.register(reg.check_mesh(v, f), reg.Registration().fast())
    assert e.value.residual_mm > reg.Registration().max_residual_mm


def test_register_command_writes_the_fit_and_landmarks_or_nothing(tmp_path, capsys):
    scan = scans.make_scan(4546, remeshing="decimated", units="m")
    path = tmp_path / "me.ply"
    trimesh.Trimesh(scan.vertices, scan.faces, process=False).export(path)
    out = tmp_path / "fit" / "fitted.obj"
    assert cli(["register", "--mesh", str(path), "--out", str(out)]) == 0
    fitted = trimesh.load(out, process=False, maintain_order=True)
    np.testing.assert_array_equal(fitted.faces, T.faces)
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["units"] == "m" and np.array(record["landmarks"]).shape == (68, 3)
    error_mm = np.linalg.norm(np.array(record["landmarks"]) - scan.truth_landmarks, axis=1) * 1000
    assert np.median(error_mm) < 1.5
    with pytest.raises(SystemExit):
        cli(["register", "--mesh", str(path), "--units", "mm", "--out", str(tmp_path / "no" / "x.obj")])
    assert "--units mm contradicts its size; it looks like m" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli(["register", "--mesh", str(path), "--set", "stiffnes=1", "--out", str(tmp_path / "no" / "x.obj")])
    assert "NAME a setting of registration" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli(["register", "--mesh", str(path), "--set", "trim=0.1", "--out", str(tmp_path / "no" / "x.obj")])
    assert "trim must be in [0.5, 1]" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()


@st.composite
def bad_mesh(draw):
    """(vertices, faces, what the error must say): a face-sized mesh with exactly one defect."""
    v = np.array(T.vertices, dtype=np.float64)
    f = np.array(T.faces)
    defect = draw(st.sampled_from(["nan", "inf", "index", "negative", "no faces", "flat faces", "quads",
                                   "2-d vertices", "too few", "tiny", "huge", "float faces"]))
    if defect in ("nan", "inf"):
        v[draw(st.integers(0, len(v) - 1)), draw(st.integers(0, 2))] = np.nan if defect == "nan" else -np.inf
        return v, f, "with NaN or inf"
    if defect in ("index", "negative"):
        f[draw(st.integers(0, len(f) - 1)), draw(st.integers(0, 2))] = len(v) + 3 if defect == "index" else -1
        return v, f, "index vertices outside"
    if defect == "no faces":
        return v, np.zeros((0, 3), int), "no triangles"
    if defect in ("flat faces", "quads"):
        return v, (f.ravel()[:99] if defect == "flat faces" else np.zeros((10, 4), int)), "(K, 3) integer triangles"
    if defect == "float faces":
        return v, f.astype(float), "(K, 3) integer triangles"
    if defect == "2-d vertices":
        return v[:, :2], f, "no vertices of shape (V, 3)"
    if defect == "too few":
        n = draw(st.integers(3, 299))
        return v[:n], f[(f < n).all(1)][:1] if (f < n).all(1).any() else np.array([[0, 1, 2]]), "allowed: 300"
    # Scales at which the 210 mm tall face fits no unit's range (80-500 mm in mm, cm or m).
    scale = draw(st.sampled_from([1e-4, 3e-3, 0.3, 3.0]) if defect == "tiny" else st.floats(5e3, 1e6))
    return v * scale, f, "a face mesh is 80-500 mm across"


@settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(case=bad_mesh(), units=st.sampled_from([None, "mm", "cm", "m"]))
def test_generated_bad_meshes_get_a_clear_error(case, units):
    """One defect at a time: a ValueError that names it (never an IndexError or a silent mesh)."""
    vertices, faces, message = case
    with pytest.raises(ValueError) as e:
        reg.check_mesh(vertices, faces, units)
    text = str(e.value)
    assert message in text or (units is not None and "contradicts its size" in text), text


def test_a_template_mesh_of_any_identity_in_the_canonical_pose_is_animated_without_registration():
    # `python -m facelib neutral` writes other identities whose rigid fit onto the template moves them by up to
    # 4.4 mm: they are in the canonical pose all the same; a turned or moved copy is not
    from facelib import pipeline
    from facelib.face import Face, sample_identity
    faces = get_template().faces
    for seed in (0, 3, 7):
        assert pipeline.is_canonical_template(reg.UserMesh(Face(sample_identity(seed)).neutral, faces, "mm"))
    v = Face(sample_identity(3)).neutral
    c, a = v.mean(0), np.radians(5)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    assert not pipeline.is_canonical_template(reg.UserMesh((v - c) @ turn.T + c, faces, "mm"))
    assert not pipeline.is_canonical_template(reg.UserMesh(v + [20.0, 0, 0], faces, "mm"))
    small = np.radians(1)  # within the world's own turn: still canonical
    turn = np.array([[np.cos(small), 0, np.sin(small)], [0, 1, 0], [-np.sin(small), 0, np.cos(small)]])
    assert pipeline.is_canonical_template(reg.UserMesh((v - c) @ turn.T + c, faces, "mm"))

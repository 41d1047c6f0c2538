"""Mesh files in and out: OBJ with a topology check, animations written all or nothing."""
import numpy as np
import pytest
import trimesh

from facelib import meshio as io
from facelib.face import Face, sample_identity, template as tpl


T = tpl.get_template()


def test_obj_round_trip_keeps_vertices_and_topology(face_obj):
    v = io.read_neutral_mesh(face_obj)
    np.testing.assert_allclose(v, Face(sample_identity(31)).neutral, atol=1e-5)
    back = trimesh.load(face_obj, process=False, maintain_order=True)
    np.testing.assert_array_equal(back.faces, T.faces)


def test_meshes_of_another_topology_are_refused(tmp_path, face_obj):
    sphere = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(2).export(sphere)
    with pytest.raises(ValueError, match=f"the template topology has {T.num_vertices} vertices and {len(T.faces)} triangles"):
        io.read_neutral_mesh(sphere)
    flipped = tmp_path / "flipped.obj"
    io.write_obj(flipped, io.read_neutral_mesh(face_obj), T.faces[:, ::-1])
    with pytest.raises(ValueError, match="other triangles"):
        io.read_neutral_mesh(flipped)
    nan = tmp_path / "nan.obj"
    v = io.read_neutral_mesh(face_obj)
    v[100] = np.nan
    io.write_obj(nan, v)
    with pytest.raises(ValueError, match="1 non-finite vertices"):
        io.read_neutral_mesh(nan)
    with pytest.raises(ValueError, match="does not exist"):
        io.read_neutral_mesh(tmp_path / "missing.obj")


def test_write_animation_is_all_or_nothing(tmp_path):
    meshes = np.repeat(T.vertices[None], 3, 0)
    written = io.write_animation(tmp_path / "ok", meshes, extra={"note.txt": b"x"})
    assert sorted(p.name for p in written) == ["frame_000.obj", "frame_001.obj", "frame_002.obj", "note.txt"]
    with pytest.raises(Exception):
        io.write_animation(tmp_path / "half", meshes, gif=b"GIF89a", extra={"note.txt": "not bytes"})
    assert not (tmp_path / "half").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".half")]  # the temporary folder is gone

"""Mesh files in and out (facelib.meshio) and the end-to-end command `python -m facelib animate`."""
import json

import numpy as np
import pytest
import trimesh

from facelib import __main__ as cli
from facelib import meshio as io
from facelib.face import Face, sample_identity
from facelib.face import template as tpl

T = tpl.get_template()


@pytest.fixture(scope="module")
def face_obj(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "face.obj"
    assert cli.main(["neutral", "--seed", "31", "--out", str(path)]) == 0
    return path


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


def test_animate_writes_obj_frames_a_gif_and_the_landmarks(tmp_path, face_obj):
    out = tmp_path / "anim"
    assert cli.main(["animate", "--mesh", str(face_obj), "--label", "mouth_open", "--steps", "2", "--out", str(out)]) == 0
    objs = sorted(out.glob("frame_*.obj"))
    assert len(objs) == 40 and (out / "animation.gif").stat().st_size > 1000
    first, last = (trimesh.load(p, process=False, maintain_order=True) for p in (objs[0], objs[-1]))
    np.testing.assert_array_equal(first.faces, T.faces)
    neutral = io.read_neutral_mesh(face_obj)
    assert np.abs(first.vertices - neutral).max() < 0.5  # N2E: frame 1 is (nearly) the neutral face
    assert np.abs(last.vertices - neutral).max() > 1.0  # and the face moves
    with np.load(out / "landmarks.npz") as f:
        assert f["landmarks"].shape == (1, 40, 68, 3)
        assert json.loads(str(f["config"]))["label"] == "mouth_open"


@pytest.mark.parametrize("args, message", [
    (["--label", "wink"], "unknown label"),
    (["--label", "mouth_open", "--mesh", "SPHERE"], "the template topology has"),
    (["--label", "mouth_open", "--steps", "0"], "steps must be a positive integer, got 0"),
])
def test_animate_refuses_bad_input_and_writes_nothing(tmp_path, face_obj, capsys, args, message):
    sphere = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(2).export(sphere)
    argv = ["animate", "--mesh", str(face_obj), "--steps", "2", "--out", str(tmp_path / "out")] + args
    argv = [str(sphere) if a == "SPHERE" else a for a in argv]
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()

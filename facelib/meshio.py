"""Mesh files in and out (the end-to-end chapter; ``python -m facelib animate``): OBJ
read with a topology check, an animated sequence written as one OBJ per frame plus a
GIF, all or nothing.  Named so that it shadows no standard module; it imports nothing
above the face world."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np

from .face import template as tpl


def read_neutral_mesh(path):
    """Vertices (V, 3) float32 of a mesh file (OBJ, PLY, ...) that has the template's
    topology: the same vertex count and the same triangles, in the same order.  Anything
    else is refused with the counts expected, since the networks index the template's
    vertices."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"mesh file {path} does not exist")
    try:
        mesh = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ValueError(f"cannot read {path} as a mesh: {e}") from e
    t = tpl.get_template()
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if v.shape != t.vertices.shape or f.shape != t.faces.shape:
        raise ValueError(
            f"{path} has {len(v)} vertices and {len(f)} triangles; the template"
            f" topology has {t.num_vertices} vertices and {len(t.faces)} triangles"
            " (register the mesh to the template first, or start from one written by"
            " `python -m facelib neutral`)"
        )
    if not np.array_equal(f, t.faces):
        raise ValueError(
            f"{path} has the template's vertex and triangle counts but other triangles:"
            " its vertices are not in the template's order"
        )
    try:
        return tpl.check_neutral_mesh(v)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def write_obj(path, vertices, faces=None):
    """One OBJ file of a mesh (by default of the template topology, vertices in mm)."""
    import trimesh

    faces = tpl.get_template().faces if faces is None else faces
    trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64), faces, process=False
    ).export(path)


def write_animation(
    out_dir, meshes, gif=None, extra=None, faces=None, template_meshes=None
):
    """Write ``frame_000.obj`` ... (one per mesh of (F, V, 3), with triangles ``faces``,
    by default the template's), ``animation.gif`` (``gif``: its bytes, e.g. from
    viz.gif_bytes), ``extra`` {file name: bytes} and, given ``template_meshes`` (F,
    V_template, 3), ``template/frame_000.obj`` ... into ``out_dir``.  Everything is
    first written to a temporary folder beside it and moved in only when complete, so an
    error leaves nothing half-way. Returns the list of written paths."""
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    meshes = np.asarray(meshes)
    digits = max(3, len(str(len(meshes) - 1)))
    with tempfile.TemporaryDirectory(
        dir=out_dir.parent, prefix=f".{out_dir.name}-"
    ) as tmp:
        tmp = Path(tmp)
        for f, m in enumerate(meshes):
            write_obj(tmp / f"frame_{f:0{digits}d}.obj", m, faces)
        if template_meshes is not None:
            (tmp / "template").mkdir()
            for f, m in enumerate(template_meshes):
                write_obj(tmp / "template" / f"frame_{f:0{digits}d}.obj", m)
        if gif is not None:
            (tmp / "animation.gif").write_bytes(gif)
        for name, content in (extra or {}).items():
            (tmp / name).write_bytes(content)
        out_dir.mkdir(exist_ok=True)
        written = []
        for p in sorted(tmp.iterdir()):
            if p.is_dir() and (out_dir / p.name).is_dir():
                shutil.rmtree(out_dir / p.name)  # a template/ folder of an earlier run
            shutil.move(str(p), out_dir / p.name)
            written.append(out_dir / p.name)
    return written

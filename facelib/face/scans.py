"""Synthetic "scans": a world face as a reader's mesh might arrive (the chapter "Your
own face").

A :class:`Scan` is a face of the world re-triangulated (subdivided, decimated,
remeshed), in other units and another pose, with noise, holes or extra components,
together with its truth: the pose and units that were applied, the true landmarks, and
the true motion of every scan vertex for a given expression.  The truth tables of
facelib/registration.py's evaluation (benchmarks/registration.py) are built from these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .. import config
from . import identity
from . import template as tpl
from .aus import Face, au_vector, vertex_normals
from .expressions import RECIPES
from .surface import closest_points, interpolate

REMESHINGS = ("subdivided", "decimated", "remeshed")


def decimate(vertices, faces, target):
    """Quadric-error decimation (Garland & Heckbert 1997, VTK's vtkQuadricDecimation
    through pyvista) to about ``target`` vertices: (vertices, faces)."""
    import pyvista as pv

    mesh = pv.PolyData(
        np.asarray(vertices, float),
        np.hstack([np.full((len(faces), 1), 3), faces]).ravel(),
    )
    out = mesh.decimate(1.0 - target / len(vertices))
    return np.asarray(out.points, dtype=np.float64), out.faces.reshape(-1, 4)[
        :, 1:
    ].astype(np.int64)


def drop_unused(vertices, faces):
    """(vertices, faces, the kept vertices' old indices) without the vertices no
    triangle uses."""
    used = np.unique(faces)
    new_index = np.full(len(vertices), -1)
    new_index[used] = np.arange(len(used))
    return vertices[used], new_index[faces], used


def remesh(vertices, faces, kind):
    """The face re-triangulated: "subdivided" (each triangle split in four, about 16k
    vertices), "decimated" (quadric decimation to about 2k vertices) or "remeshed"
    (split to edges of at most 1 mm, about 140k vertices, then decimated to about 20k:
    none of the template's vertices or edges survive)."""
    import trimesh

    if kind == "subdivided":
        return trimesh.remesh.subdivide(vertices, faces)
    if kind == "decimated":
        return decimate(vertices, faces, 2000)
    if kind == "remeshed":
        fine = trimesh.Trimesh(
            *trimesh.remesh.subdivide_to_size(vertices, faces, max_edge=1.0)
        )
        fine.merge_vertices()
        return decimate(fine.vertices, fine.faces, 20000)
    raise ValueError(f"unknown remeshing {kind!r}; allowed: {', '.join(REMESHINGS)}")


def cut_holes(vertices, faces, centres, radius):
    """Remove every triangle with a vertex within ``radius`` mm of one of ``centres``
    (k, 3): (vertices, faces, the kept vertices' old indices)."""
    d = np.linalg.norm(vertices[:, None] - np.asarray(centres)[None], axis=-1).min(1)
    return drop_unused(vertices, faces[(d[faces] > radius).all(1)])


def eyeballs(neutral, radius=12.0):
    """Two separate sphere components behind the eyes of a neutral mesh: (vertices,
    faces)."""
    import trimesh

    t = tpl.get_template()
    parts = []
    for eye in (range(36, 42), range(42, 48)):
        centre = neutral[t.landmark_index[list(eye)]].mean(0) - [0.0, 0.0, radius - 1.0]
        s = trimesh.creation.icosphere(subdivisions=3, radius=radius)
        parts.append((s.vertices + centre, s.faces))
    return parts


def back_of_head(neutral):
    """The back half of an ellipsoid behind a neutral face (a separate component, as a
    head scan's skull and hair would be): (vertices, faces)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=95.0)
    centre = np.array([0.0, 10.0, neutral[:, 2].min() - 20.0])
    v = sphere.vertices * [0.85, 1.1, 1.0] + centre
    back = v[:, 2] < centre[2] + 30.0
    v, f, _ = drop_unused(v, sphere.faces[back[sphere.faces].all(1)])
    return v, f


def append(vertices, faces, parts):
    """The mesh with extra components appended (each part keeps its own triangles)."""
    for v, f in parts:
        faces = np.concatenate([faces, f + len(vertices)])
        vertices = np.concatenate([vertices, v])
    return vertices, faces


def apex_weights(label):
    """AU intensities at the middle of each range of the label's recipe (its typical
    apex)."""
    return au_vector(**{name: (lo + hi) / 2 for name, lo, hi in RECIPES[label].aus})


def bumps(vertices, normals, rng, count=12, amplitude=2.0, width=18.0):
    """A smooth field outside the identity model: ``count`` Gaussian bumps of up to
    ``amplitude`` mm along the normals, ``width`` mm wide, at random vertices."""
    centres = vertices[rng.choice(len(vertices), count, replace=False)]
    heights = rng.uniform(-amplitude, amplitude, count)
    d2 = ((vertices[:, None] - centres[None]) ** 2).sum(-1)
    return vertices + normals * (np.exp(-d2 / (2 * width**2)) @ heights)[:, None]


@dataclass(frozen=True)
class Scan:
    """A face as a reader's mesh, with its truth.  ``vertices`` are in ``units`` and the
    scan's pose: vertices * mm_per_unit = rotation applied to the face's canonical mm
    coordinates + translation.  ``face_vertex`` marks the vertices of the face surface
    (not of extra components); ``truth_landmarks`` (68, 3) and ``truth_motion`` (label
    -> (V_scan, 3)) are in the scan's units and pose, and so is ``template_motion``
      (label -> (V_template, 3)), the true motion of each template vertex of this
      face."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    units: str
    rotation: np.ndarray
    translation: np.ndarray
    face_vertex: np.ndarray
    truth_landmarks: np.ndarray
    truth_motion: dict
    template_motion: dict


def make_scan(
    seed,
    remeshing="remeshed",
    units="mm",
    noise_mm=0.0,
    holes=0,
    extra=False,
    head=False,
    out_of_model=False,
    labels=("high_smile", "mouth_open", "eyebrow"),
    name=None,
):
    """A :class:`Scan` of the unseen identity drawn from ``seed`` (the datasets draw
    theirs from other seeds), in a random pose (a uniformly random rotation, a
    translation of up to 300 mm), re-triangulated by ``remeshing``. ``extra``: two
    eyeballs as separate components; ``head``: the back of a head behind the face
    (back_of_head). ``out_of_model``: identity coefficients 1.5 times as large and a
    smooth bump field added, a face the identity model cannot fit exactly.  ``labels``:
    the expressions whose true motion is recorded.
    """
    rng = np.random.default_rng([seed, 45])
    t = tpl.get_template()
    coeffs = identity.sample_identity(rng) * (1.5 if out_of_model else 1.0)
    face = Face(coeffs)
    neutral = np.asarray(face.neutral, dtype=np.float64)
    motion = {
        label: (
            np.asarray(face.expression(apex_weights(label)), dtype=np.float64) - neutral
        )
        for label in labels
    }
    if out_of_model:
        offset = bumps(neutral, vertex_normals(neutral, t.faces), rng) - neutral
        neutral = neutral + offset
    landmarks = neutral[t.landmark_index]
    v, f = remesh(neutral, t.faces, remeshing)
    # Each new vertex lies on (or, after decimation, within a fraction of a millimetre
    # of) the true neutral surface: its true motion is the motion at its closest point
    # there.
    tri, bary, _ = closest_points(neutral, t.faces, v)
    vertex_motion = {k: interpolate(m, t.faces, tri, bary) for k, m in motion.items()}
    if holes:
        # Holes away from the landmarks (cheeks, forehead, temples): a scan's typical
        # gaps.
        far = np.linalg.norm(v[:, None] - landmarks[None], axis=-1).min(1) > 15.0
        v, f, kept = cut_holes(
            v, f, v[rng.choice(np.flatnonzero(far), holes, replace=False)], 8.0
        )
        vertex_motion = {k: m[kept] for k, m in vertex_motion.items()}
    is_face = np.ones(len(v), bool)
    if extra or head:
        parts = (eyeballs(neutral) if extra else []) + (
            [back_of_head(neutral)] if head else []
        )
        n_before = len(v)
        v, f = append(v, f, parts)
        is_face = np.arange(len(v)) < n_before
        vertex_motion = {
            k: np.concatenate([m, np.zeros((len(v) - n_before, 3))])
            for k, m in vertex_motion.items()
        }
    if noise_mm:
        v = v + rng.normal(0.0, noise_mm, v.shape)
    rotation = Rotation.random(random_state=rng).as_matrix()
    translation = rng.uniform(-300.0, 300.0, 3)
    scale = config.UNITS_MM[units]
    return Scan(
        name or remeshing,
        (v @ rotation.T + translation) / scale,
        f,
        units,
        rotation,
        translation,
        is_face,
        (landmarks @ rotation.T + translation) / scale,
        {k: m @ rotation.T / scale for k, m in vertex_motion.items()},
        {k: m @ rotation.T / scale for k, m in motion.items()},
    )


def not_faces():
    """Meshes that are not faces, each about a face's size (mm): name -> (vertices,
    faces)."""
    import trimesh

    fingers = [trimesh.creation.capsule(height=60.0, radius=9.0) for _ in range(4)]
    for k, finger in enumerate(fingers):
        finger.apply_transform(
            trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
        )
        finger.apply_translation([-33.0 + 22.0 * k, 80.0, 0.0])
    hand = trimesh.util.concatenate(
        [trimesh.creation.box([90.0, 100.0, 25.0]), *fingers]
    )
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=80.0)
    cube = trimesh.creation.box([150.0, 150.0, 150.0])
    cube_v, cube_f = trimesh.remesh.subdivide_to_size(
        cube.vertices, cube.faces, max_edge=10.0
    )
    square = np.array(
        [
            [-80.0, -100.0, 0.0],
            [80.0, -100.0, 0.0],
            [80.0, 100.0, 0.0],
            [-80.0, 100.0, 0.0],
        ]
    )
    plane = trimesh.remesh.subdivide_to_size(
        square, np.array([[0, 1, 2], [0, 2, 3]]), max_edge=5.0
    )
    return {
        "sphere": (sphere.vertices, sphere.faces),
        "cube": (cube_v, cube_f),
        "hand": (hand.vertices, hand.faces),
        "plane": plane,
    }

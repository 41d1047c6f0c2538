"""End to end (paper §3.3, the end-to-end chapter): a neutral mesh -> its landmarks ->
geometry-adaptive generation of an expression (Alg. 4, with the book's defaults,
tasks.GeometryAdaptive), or a schedule of expressions of any length streamed window
by window (tasks.long, the chapter "Any length") -> the landmark-guided deformation of
the mesh (facelib/deformation.py).  A mesh of another topology, units or pose is first
registered (facelib/registration.py, the chapter "Your own face") and the motion
carried back to its own vertices.
"""

from __future__ import annotations

import time

from dataclasses import dataclass

import numpy as np

from . import checks, config, deformation, registration, tasks
from .face import COMA_LABELS
from .face import template as tpl


def animate(
    neutral_vertices,
    label,
    settings=tasks.GeometryAdaptive(),
    model=None,
    denoiser=None,
    guide=None,
    progress=False,
    **overrides,
):
    """End to end (the end-to-end chapter): a neutral mesh (V, 3) of the template
    topology -> its landmarks -> geometry-adaptive generation of ``label`` (Alg. 4 with
    ``settings``, by default the book's: one pass, reconstruction guidance;
    ``overrides`` such as order="E2N", steps=50, seed=1) -> deformation. Returns (meshes
    (F, V, 3), landmarks (F, 68, 3), seconds per stage)."""
    if label not in COMA_LABELS:
        raise ValueError(
            f"unknown label {label!r}; allowed (the CoMA-like set the models were"
            f" trained on): {', '.join(COMA_LABELS)}"
        )
    return _generate_and_deform(
        neutral_vertices,
        lambda face: tasks.geometry_adaptive(
            face, label, 1, settings, denoiser, guide, progress, **overrides
        )[0],
        model,
    )


def animate_schedule(
    neutral_vertices,
    schedule,
    settings=tasks.Long(),
    model=None,
    denoiser=None,
    guide=None,
    progress=False,
    **overrides,
):
    """:func:`animate` for a schedule of any length (the chapter "Any length"): a string
    such as "high_smile:3s, neutral:1s, 'a broad grin':2s" (tasks.long.read_schedule) or
    a list of Segments, streamed by tasks.long.long_sequence with ``settings``
    (tasks.Long; the frames at ``settings.fps``). Returns (meshes (F, V, 3),
    landmarks (F, 68, 3), seconds per stage)."""
    settings = checks.with_overrides(settings, overrides)
    if isinstance(schedule, str):
        schedule = tasks.long.read_schedule(schedule, settings)
    return _generate_and_deform(
        neutral_vertices,
        lambda face: tasks.long.long_sequence(
            face, schedule, 1, settings, denoiser, guide, progress
        )[0],
        model,
    )


def _generate_and_deform(neutral_vertices, generate, model):
    """(meshes, landmarks, seconds per stage) of a neutral mesh animated by the
    landmark sequence that ``generate`` makes from its landmarks (68, 3)."""
    seconds = {}
    t0 = time.perf_counter()
    neutral = tpl.check_neutral_mesh(neutral_vertices)
    landmarks0 = neutral[tpl.get_template().landmark_index]
    seconds["landmarks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    landmarks = generate(landmarks0)
    seconds["generation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    meshes = deformation.deform(neutral, landmarks, model=model)
    seconds["deformation"] = time.perf_counter() - t0
    return meshes, landmarks, seconds


@dataclass
class Animation:
    """What :func:`animate_mesh` made: ``frames`` (F, V_user, 3) on the user's mesh (its
    units, pose, vertices and triangles), ``template_frames`` (F, V, 3) the fitted
    template's (canonical pose, mm), the generated landmarks (F, 68, 3), the
    registration (None when the mesh already was a canonical template mesh) and seconds
    per stage.
    """

    frames: np.ndarray
    template_frames: np.ndarray
    landmarks: np.ndarray
    registration: registration.FittedTemplate | None
    seconds: dict


def is_canonical_template(
    mesh,
    max_degrees=config.CANONICAL_POSE_DEGREES,
    max_shift_mm=config.CANONICAL_POSE_SHIFT_MM,
):
    """True when ``mesh`` (a registration.UserMesh) has the template's triangles and
    lies in the canonical pose in mm (as `python -m facelib neutral` writes it): the
    rigid fit onto the template turns it by at most ``max_degrees`` and moves its
    centre by at most ``max_shift_mm`` (another identity's shape moves the fit too,
    so the vertices themselves are not compared).  It is animated as it is, with no
    registration.
    """
    t = tpl.get_template()
    if (
        mesh.units != "mm"
        or mesh.vertices.shape != t.vertices.shape
        or not np.array_equal(mesh.faces, t.faces)
    ):
        return False
    _, r, shift = registration.similarity(mesh.vertices, t.vertices, scale=False)
    degrees = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))
    centre = mesh.vertices.mean(0)
    moved = np.linalg.norm(centre @ r.T + shift - centre)
    return bool(degrees <= max_degrees and moved <= max_shift_mm)


def animate_mesh(
    mesh,
    label=None,
    registration_settings=registration.Registration(),
    progress=False,
    schedule=None,
    **overrides,
):
    """A reader's mesh (registration.UserMesh: any topology, units, pose) animated with
    ``label`` or a ``schedule``: registration (unless it is a canonical template mesh),
    :func:`animate` (:func:`animate_schedule`) on the fitted template, the motion
    carried back (FittedTemplate.transfer).  ``overrides`` go to :func:`animate` (order,
    steps, seed...) or :func:`animate_schedule` (fps, steps, seed...).
    """
    if (label is None) == (schedule is None):
        raise ValueError("give a label or a schedule (one of them)")
    seconds = {}
    if is_canonical_template(mesh):
        fit, neutral = None, mesh.vertices
    else:
        t0 = time.perf_counter()
        fit = registration.register(mesh, registration_settings)
        neutral = fit.neutral
        seconds["registration"] = time.perf_counter() - t0
    template_frames, landmarks, stages = (
        animate(neutral, label, progress=progress, **overrides)
        if schedule is None
        else animate_schedule(neutral, schedule, progress=progress, **overrides)
    )
    seconds.update(stages)
    t0 = time.perf_counter()
    frames = template_frames if fit is None else fit.transfer(template_frames)
    seconds["transfer"] = time.perf_counter() - t0
    return Animation(
        np.asarray(frames), np.asarray(template_frames), landmarks, fit, seconds
    )

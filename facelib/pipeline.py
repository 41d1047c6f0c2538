"""End to end (paper §3.3, the end-to-end chapter): a neutral mesh -> its landmarks -> geometry-adaptive generation
of an expression (Alg. 4, with the book's defaults, config.GeometryAdaptive) -> the landmark-guided
deformation of the mesh (facelib/deformation.py)."""
from __future__ import annotations

import time

from . import config, deformation, tasks
from .face import COMA_LABELS
from .face import template as tpl


def animate(neutral_vertices, label, settings=config.GeometryAdaptive(), model=None, denoiser=None, guide=None,
            progress=False, **overrides):
    """End to end (the end-to-end chapter): a neutral mesh (V, 3) of the template topology -> its landmarks ->
    geometry-adaptive generation of ``label`` (Alg. 4 with ``settings``, by default the book's: one pass,
    reconstruction guidance; ``overrides`` such as order="E2N", steps=50, seed=1) -> deformation.
    Returns (meshes (F, V, 3), landmarks (F, 68, 3), seconds per stage)."""
    if label not in COMA_LABELS:
        raise ValueError(f"unknown label {label!r}; allowed (the CoMA-like set the models were trained on): "
                         f"{', '.join(COMA_LABELS)}")
    seconds = {}
    t0 = time.perf_counter()
    neutral = tpl.check_neutral_mesh(neutral_vertices)
    landmarks0 = neutral[tpl.get_template().landmark_index]
    seconds["landmarks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    landmarks = tasks.geometry_adaptive(landmarks0, label, 1, settings, denoiser, guide, progress, **overrides)[0]
    seconds["generation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    meshes = deformation.deform(neutral, landmarks, model=model)
    seconds["deformation"] = time.perf_counter() - t0
    return meshes, landmarks, seconds

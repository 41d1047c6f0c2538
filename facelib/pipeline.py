"""End to end (paper §3.3, chapter 10): a neutral mesh -> its landmarks -> geometry-adaptive generation
of an expression (Alg. 4, with the book's defaults, config.GeometrySampling) -> the landmark-guided
deformation of the mesh (facelib/deformation.py)."""
from __future__ import annotations

import time

from . import config, deformation, tasks
from .face import COMA_LABELS
from .face import template as tpl


def animate(neutral_vertices, label, order="N2E", steps=None, seed=0, model=None, denoiser=None, guide=None,
            progress=False):
    """End to end (chapter 10): a neutral mesh (V, 3) of the template topology -> its landmarks ->
    geometry-adaptive generation of ``label`` (Alg. 4, with the book's reconstruction guidance) ->
    deformation.  steps: reverse steps (None: config.GeometrySampling's).
    Returns (meshes (F, V, 3), landmarks (F, 68, 3), seconds per stage)."""
    defaults = config.GeometrySampling()
    if label not in COMA_LABELS:
        raise ValueError(f"unknown label {label!r}; allowed (the CoMA-like set the models were trained on): "
                         f"{', '.join(COMA_LABELS)}")
    seconds = {}
    t0 = time.perf_counter()
    neutral = tpl.check_neutral_mesh(neutral_vertices)
    landmarks0 = neutral[tpl.get_template().landmark_index]
    seconds["landmarks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    steps = defaults.steps if steps is None else steps
    landmarks = tasks.geometry_adaptive(landmarks0, label, order=order, steps=steps, seed=seed,
                                        passes=defaults.passes, reconstruction_scale=defaults.reconstruction_scale,
                                        denoiser=denoiser, guide=guide, progress=progress)[0]
    seconds["generation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    meshes = deformation.deform(neutral, landmarks, model=model)
    seconds["deformation"] = time.perf_counter() - t0
    return meshes, landmarks, seconds

"""Training: one loop (:mod:`facelib.training.loop`) and one recipe per model
(:mod:`facelib.training.recipes`).

    model, history = training.fit(training.recipe("denoiser", steps=100))
    # python -m facelib train guide --dataset bu --type S:
    training.train_and_save(training.recipe("guide", dataset="bu", classifier_type="S"))
    training.train_all()  # python -m facelib train all

The same loop runs unchanged under ``torchrun --nproc_per_node N -m facelib train NAME``
(distributed data parallel; see the loop's docstring).  Every recipe's settings, with
their defaults and sources, are in facelib/training/settings.py (``training.
DenoiserTraining()``, ...).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

from ..checkpoints import check_world, checkpoint_paths, save_checkpoint
from ..checks import with_overrides
from .loop import Draws, TrainingLog, fit, is_main_process
from .recipes import (
    RECIPES,
    SETTINGS,
    ActorRecipe,
    AURegressorRecipe,
    DeformationRecipe,
    DenoiserRecipe,
    DistillationRecipe,
    EvaluatorRecipe,
    GuideRecipe,
    LSTMFillerRecipe,
    Motion3DGANRecipe,
    MotionClipRecipe,
    TextHeadRecipe,
    swap_anatomy,
    text_head_loss,
    training_anatomies,
)
from .settings import (
    AURegressorTraining,
    ActorTraining,
    DeformationTraining,
    DenoiserTraining,
    DistillationTraining,
    EvaluatorTraining,
    GuideTraining,
    LSTMFillerTraining,
    Motion3DGANTraining,
    MotionClipTraining,
    Optimisation,
    TextHeadTraining,
)
from .shipped import SHIPPED

__all__ = [
    "AURegressorTraining",
    "ActorTraining",
    "DeformationTraining",
    "DenoiserTraining",
    "DistillationTraining",
    "EvaluatorTraining",
    "GuideTraining",
    "LSTMFillerTraining",
    "Motion3DGANTraining",
    "MotionClipTraining",
    "Optimisation",
    "TextHeadTraining",
    "Draws",
    "TrainingLog",
    "fit",
    "is_main_process",
    "RECIPES",
    "SETTINGS",
    "ActorRecipe",
    "AURegressorRecipe",
    "DeformationRecipe",
    "DenoiserRecipe",
    "DistillationRecipe",
    "EvaluatorRecipe",
    "GuideRecipe",
    "LSTMFillerRecipe",
    "Motion3DGANRecipe",
    "MotionClipRecipe",
    "TextHeadRecipe",
    "swap_anatomy",
    "text_head_loss",
    "training_anatomies",
    "SHIPPED",
    "recipe",
    "settings_for",
    "save_trained",
    "train_and_save",
    "train_all",
]


def recipe(model_name, fast=False, **settings):
    """The recipe of a model by name (``RECIPES``) with its default settings changed by
    ``settings`` (:func:`settings_for`)."""
    chosen = settings_for(model_name, fast, **settings)
    return RECIPES[model_name](chosen)


def settings_for(model_name, fast=False, **settings):
    """A model's training settings: its defaults (facelib/training/settings.py)
    changed by ``settings``.

    ``steps`` keeps the warm-up at most a tenth of the run
    (``Optimisation.with_steps``); ``fast``: the settings' fast-mode version (a few
    steps, for tests and FACELIB_FAST chapters)."""
    if model_name not in RECIPES:
        raise ValueError(f"unknown model {model_name!r}; allowed: {', '.join(RECIPES)}")
    steps = settings.pop("steps", None)  # a field of every recipe's settings
    chosen = with_overrides(SETTINGS[model_name](), settings, name=model_name)
    if steps is not None:
        if chosen.epochs is not None:
            raise ValueError(
                f"{model_name} trains for a number of epochs ({chosen.epochs}): set"
                " epochs, not steps"
            )
        chosen = chosen.with_steps(steps)
    return chosen.fast() if fast else chosen


def trained_on_this_world(name, model=None, settings=None, fast=False):
    """True if checkpoint ``name`` exists, was trained on the world this process builds
    and, when ``model`` and ``settings`` are given, with the settings of that recipe
    (settings_for, ``fast``) that it records.
    """
    pt, js = checkpoint_paths(name)
    if not (pt.exists() and js.exists()):
        return False
    meta = json.loads(js.read_text())
    try:
        check_world(meta, pt.name)
    except ValueError:
        return False
    if model is None:
        return True
    recorded = meta.get("training", {})
    wanted = asdict(settings_for(model, fast, **settings))
    return all(
        recorded[k] == (list(v) if isinstance(v, tuple) else v)
        for k, v in wanted.items()
        if k in recorded
    )


def save_trained(recipe, model, history, name=None, **metadata):
    """Write a trained model's checkpoint (weights + JSON with its config, settings,
    loss curves and ``metadata``, e.g. the training's wall time)."""
    return save_checkpoint(
        name or recipe.checkpoint_name(),
        model,
        recipe.kind,
        recipe.model_config(model),
        history=history,
        **recipe.metadata(model),
        **metadata,
    )


def train_and_save(recipe, name=None, progress=True, device=None, resume=False):
    """Train a recipe (or a model by name with its defaults) and save it; only rank 0
    writes.

    Returns the checkpoint paths (.pt, .json), or None on the other ranks of a
    distributed run.
    """
    recipe = RECIPES[recipe]() if isinstance(recipe, str) else recipe
    stem = checkpoint_paths(name or recipe.checkpoint_name())[0].with_suffix("")
    resumed = resume and stem.with_suffix(".state.pt").exists()
    t0 = time.perf_counter()
    model, history = fit(
        recipe, progress=progress, device=device, resume_from=stem if resume else None
    )
    if not is_main_process():
        return None
    written = save_trained(
        recipe,
        model,
        history,
        name,
        wall_time_s=round(time.perf_counter() - t0, 1),
        resumed=resumed,
    )
    stem.with_suffix(".state.pt").unlink(
        missing_ok=True
    )  # the run is done: its training state goes
    return written


def train_all(
    names=None, fast=False, out_dir=None, progress=True, missing=False, resume=False
):
    """Retrain the shipped checkpoints ``names`` (None: all, in the order of SHIPPED)
    and write them to data/checkpoints (or ``out_dir``).  ``missing``: skip those that
    exist and were trained on this process's world with their recipe's current settings;
    ``resume``: continue each from the training state a stopped run left (recipes that
    walk epochs, the IC's, start over).  Returns rows [name, model, steps, seconds]; a
    run into data/checkpoints that trained something is recorded in
    results/train_all.json by the command line (``results.store_training_times``)."""
    names = list(SHIPPED) if names is None else list(names)
    unknown = [n for n in names if n not in SHIPPED]
    if unknown:
        raise ValueError(
            f"no shipped checkpoint {unknown[0]!r}; the shipped ones:"
            f" {', '.join(SHIPPED)}"
        )
    stems = {name: str(Path(out_dir) / name) if out_dir else name for name in names}
    if missing:
        names = [
            name
            for name in names
            if not trained_on_this_world(stems[name], *SHIPPED[name], fast)
        ]
    rows = []
    for name in names:
        model, settings = SHIPPED[name]
        r = recipe(model, fast=fast, **settings)
        t0 = time.perf_counter()
        train_and_save(
            r,
            name=stems[name],
            progress=progress,
            resume=resume and r.settings.epochs is None,
        )
        rows.append(
            [
                name,
                model,
                r.settings.epochs or r.settings.steps,
                time.perf_counter() - t0,
            ]
        )
        print(f"{name}: {rows[-1][3]:.0f} s", flush=True)
    return rows

"""Training: one loop (:mod:`facelib.training.loop`) and one recipe per model (:mod:`facelib.training.recipes`).

    model, history = training.fit(training.DenoiserRecipe(config.DenoiserTraining(steps=100)))
    training.train_and_save("guide", dataset="bu", classifier_type="S")      # python -m facelib train guide ...

The same loop runs unchanged under ``torchrun --nproc_per_node N -m facelib train NAME`` (distributed
data parallel; see the loop's docstring).  Every setting's default is in facelib/config.py.
"""
from __future__ import annotations

from dataclasses import fields, replace

from ..checkpoints import save_checkpoint
from .loop import Draws, TrainingLog, fit, is_main_process
from .recipes import (RECIPES, SETTINGS, ActorRecipe, DeformationRecipe, DenoiserRecipe, EvaluatorRecipe, GuideRecipe,
                      LSTMFillerRecipe, Motion3DGANRecipe, MotionClipRecipe, TextHeadRecipe, swap_anatomy,
                      text_head_loss, training_anatomies)


def recipe(model_name, fast=False, **settings):
    """The recipe of a model by name (``RECIPES``) with its default settings changed by ``settings``.

    ``steps`` keeps the warm-up at most a tenth of the run (``Optimisation.with_steps``); ``fast``: the
    settings' fast-mode version (a few steps, for tests and FACELIB_FAST chapters)."""
    if model_name not in RECIPES:
        raise ValueError(f"unknown model {model_name!r}; allowed: {', '.join(RECIPES)}")
    defaults = SETTINGS[model_name]()
    allowed = [f.name for f in fields(defaults)]
    unknown = sorted(set(settings) - set(allowed))
    if unknown:
        raise ValueError(f"{model_name} has no setting {', '.join(unknown)}; its settings: {', '.join(allowed)}")
    steps = settings.pop("steps", None)
    chosen = replace(defaults, **settings)
    if steps is not None:
        if chosen.epochs is not None:
            raise ValueError(f"{model_name} trains for a number of epochs ({chosen.epochs}): set epochs, not steps")
        chosen = chosen.with_steps(steps)
    return RECIPES[model_name](chosen.fast() if fast else chosen)


def save_trained(recipe, model, history, name=None):
    """Write a trained model's checkpoint (weights + JSON with its config, settings and loss curves)."""
    return save_checkpoint(name or recipe.checkpoint_name(), model, recipe.kind, recipe.model_config(model),
                           history=history, **recipe.metadata(model))


def train_and_save(recipe, name=None, progress=True, device=None, resume=False):
    """Train a recipe (or a model by name with its defaults) and save it; only rank 0 writes.

    Returns the checkpoint paths (.pt, .json), or None on the other ranks of a distributed run."""
    recipe = RECIPES[recipe]() if isinstance(recipe, str) else recipe
    stem = name or recipe.checkpoint_name()
    model, history = fit(recipe, progress=progress, device=device, resume_from=stem if resume else None)
    return save_trained(recipe, model, history, name) if is_main_process() else None

"""Training: one loop (:mod:`facelib.training.loop`) and one recipe per model (:mod:`facelib.training.recipes`).

    model, history = training.fit(training.DenoiserRecipe(config.DenoiserTraining(steps=100)))
    training.train_and_save("guide", dataset="bu", classifier_type="S")      # python -m facelib train guide ...

The same loop runs unchanged under ``torchrun --nproc_per_node N -m facelib train NAME`` (distributed
data parallel; see the loop's docstring).  Every setting's default is in facelib/config.py.
"""
from __future__ import annotations

from dataclasses import replace

from ..checkpoints import save_checkpoint
from .loop import Draws, TrainingLog, fit, start_distributed
from .recipes import (RECIPES, SETTINGS, ActorRecipe, DeformationRecipe, DenoiserRecipe, EvaluatorRecipe, GuideRecipe,
                      LSTMFillerRecipe, Motion3DGANRecipe, MotionClipRecipe, TextHeadRecipe, swap_anatomy,
                      text_head_loss, training_anatomies)


def recipe(model_name, **settings):
    """The recipe of a model by name (``RECIPES``) with its default settings changed by ``settings``."""
    if model_name not in RECIPES:
        raise ValueError(f"unknown model {model_name!r}; allowed: {', '.join(RECIPES)}")
    return RECIPES[model_name](replace(SETTINGS[model_name](), **settings))


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
    if start_distributed(device).is_main:
        return save_trained(recipe, model, history, name)
    return None

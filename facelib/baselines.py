"""The label-conditioned generative baselines of Table 1 (chapter 05), trained on the same data:

* "motion3dgan": Motion3DGAN-style WGAN-GP on SRVFs (models/motion3dgan.py; the paper's "MoGAN");
* "actor": ACTOR-style transformer CVAE (models/actor.py);

and the text-to-motion baseline of Table 2 (chapter 06):

* "motionclip": MotionCLIP-style deterministic decoder from the text embedding (models/motionclip.py).

``python -m facelib train motion3dgan --dataset coma`` (or ``actor``) retrains one; the shipped
checkpoints are ``<name>_<dataset>`` in data/checkpoints.
"""
from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np
import torch

from . import data
from .checkpoints import load_checkpoint, save_checkpoint
from .models import actor, lstm_filler, motion3dgan, motionclip

BASELINES = {
    "motion3dgan": (motion3dgan, motion3dgan.Motion3DGANTraining, motion3dgan.train_motion3dgan),
    "actor": (actor, actor.ActorTraining, actor.train_actor),
    "motionclip": (motionclip, motionclip.MotionClipTraining, motionclip.train_motionclip),
}
LABEL_BASELINES = ("motion3dgan", "actor")  # the rows of Table 1 (chapter 05)


def check_baseline(name):
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; allowed: {', '.join(BASELINES)}")
    return BASELINES[name]


def train_and_save_baseline(name, dataset="coma", steps=None, seed=0, out=None, progress=True):
    """Train a baseline on the training split of ``dataset`` and save it as <name>_<dataset>."""
    module, training, train = check_baseline(name)
    data.check_dataset_name(dataset)
    cfg = training(dataset=dataset, seed=seed)
    if steps:
        cfg = replace(cfg, steps=steps)
    model, history = train(cfg, progress=progress)
    label_names = list(data.load_dataset(dataset, "train").label_names)
    return save_checkpoint(out or f"{name}_{dataset}", model, name, module.config_dict(model),
                           training=asdict(cfg), label_names=label_names, history=history,
                           torch_version=torch.__version__)


def load_baseline(name, dataset="coma", checkpoint=None):
    """Load a shipped baseline (sha256 checked); ``model.label_names`` lists its labels."""
    module, _, _ = check_baseline(name)
    data.check_dataset_name(dataset)
    checkpoint = checkpoint or f"{name}_{dataset}"
    model, meta = load_checkpoint(checkpoint, name, module.build)
    expected = list(data.load_dataset(dataset, "train").label_names)
    if meta["label_names"] != expected:
        raise ValueError(f"checkpoint {checkpoint} generates {meta['label_names']}, dataset {dataset!r} has {expected}")
    model.label_names, model.meta = tuple(expected), meta
    return model


def generate(model, labels, seed=0):
    """Sequences (n, F, 68, 3) float32 in mm from a baseline, one per label name in ``labels``."""
    labels = [labels] if isinstance(labels, str) else list(labels)
    bad = [y for y in labels if y not in model.label_names]
    if bad or not labels:
        raise ValueError(f"unknown label {bad[0] if bad else None!r}; allowed: {', '.join(model.label_names)}")
    return model.generate(np.array([model.label_names.index(y) for y in labels]), seed=seed)


def generate_from_text(model, texts, num_frames=40, encoder=None):
    """Sequences (n, F, 68, 3) float32 in mm from the MotionCLIP-style baseline, one per text
    (deterministic: the same text always gives the same sequence)."""
    from .text import get_encoder
    texts = [texts] if isinstance(texts, str) else list(texts)
    if not texts:
        raise ValueError("need at least one text")
    return model.generate((encoder or get_encoder()).encode(texts), num_frames)


# ------------------------------------------------------------------ the learned filling baseline (Table 3)
def train_and_save_filler(dataset="coma", steps=None, seed=0, out=None, progress=True):
    """Train the bidirectional-LSTM filler (Berson et al.) and save it as lstm_filler_<dataset>."""
    data.check_dataset_name(dataset)
    cfg = lstm_filler.LSTMFillerTraining(dataset=dataset, seed=seed)
    if steps:
        cfg = replace(cfg, steps=steps)
    model, history = lstm_filler.train_lstm_filler(cfg, progress=progress)
    return save_checkpoint(out or f"lstm_filler_{dataset}", model, "lstm_filler", asdict(model.config),
                           training=asdict(cfg), normalizer=model.normalizer.to_dict(), history=history,
                           torch_version=torch.__version__)


def load_filler(dataset="coma", checkpoint=None):
    """Load the shipped LSTM filler of a dataset (sha256 checked)."""
    data.check_dataset_name(dataset)
    model, meta = load_checkpoint(checkpoint or f"lstm_filler_{dataset}", "lstm_filler",
                                  lambda c: lstm_filler.LSTMFiller(lstm_filler.LSTMFillerConfig(**c)))
    model.normalizer, model.meta = data.LandmarkNormalizer.from_dict(meta["normalizer"]), meta
    return model.eval()


@torch.no_grad()
def lstm_fill(sequences, known, filler=None, dataset="coma", seed=0):
    """Fill the unknown frames with the LSTM filler; (n, F, 68, 3) float32 mm, known frames kept exactly."""
    from .inpainting import check_fill_input, keep_known
    x, mask = check_fill_input(sequences, known)
    filler = filler or load_filler(dataset)
    xn = torch.as_tensor(filler.normalizer.normalize(x))
    out = filler.normalizer.denormalize(filler(xn, torch.as_tensor(mask), generator=torch.Generator().manual_seed(seed)))
    return keep_known(out.numpy(), x, mask)

"""The label-conditioned generative baselines of Table 1 (the label-control chapter),
trained on the same data:

* "motion3dgan": Motion3DGAN-style WGAN-GP on SRVFs (models/motion3dgan.py; the paper's
  "MoGAN");
* "actor": ACTOR-style transformer CVAE (models/actor.py);

and the text-to-motion baseline of Table 2 (the text-control chapter):

* "motionclip": MotionCLIP-style deterministic decoder from the text embedding
  (models/motionclip.py).

``python -m facelib train motion3dgan --dataset coma`` (or ``actor``) retrains one; the
shipped checkpoints are ``<name>_<dataset>`` in data/checkpoints.
"""

from __future__ import annotations


import numpy as np
import torch

from . import data
from .checkpoints import checkpoint_name, load_checkpoint
from .inpainting import check_fill_input, keep_known
from .models import actor, lstm_filler, motion3dgan, motionclip
from .text import get_encoder

BASELINES = {"motion3dgan": motion3dgan, "actor": actor, "motionclip": motionclip}
# the rows of Table 1 (the label-control chapter)
LABEL_BASELINES = ("motion3dgan", "actor")


def check_baseline(name):
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; allowed: {', '.join(BASELINES)}")
    return BASELINES[name]


def load_baseline(name, dataset="coma", checkpoint=None):
    """Load a shipped baseline (sha256 checked); ``model.label_names`` lists its
    labels."""
    module = check_baseline(name)
    data.check_dataset_name(dataset)
    checkpoint = checkpoint or checkpoint_name(name, dataset)
    model, meta = load_checkpoint(checkpoint, name, module.build)
    expected = list(data.load_dataset(dataset, "train").label_names)
    if meta["label_names"] != expected:
        raise ValueError(
            f"checkpoint {checkpoint} generates {meta['label_names']}, dataset"
            f" {dataset!r} has {expected}"
        )
    model.label_names, model.meta = tuple(expected), meta
    return model


def generate(model, labels, seed=0):
    """Sequences (n, F, 68, 3) float32 in mm from a baseline, one per label name in
    ``labels``."""
    labels = [labels] if isinstance(labels, str) else list(labels)
    bad = [y for y in labels if y not in model.label_names]
    if bad or not labels:
        raise ValueError(
            f"unknown label {bad[0] if bad else None!r}; allowed:"
            f" {', '.join(model.label_names)}"
        )
    return model.generate(
        np.array([model.label_names.index(y) for y in labels]), seed=seed
    )


def generate_from_text(model, texts, num_frames=40, encoder=None):
    """Sequences (n, F, 68, 3) float32 in mm from the MotionCLIP-style baseline, one per
    text (deterministic: the same text always gives the same sequence)."""
    texts = [texts] if isinstance(texts, str) else list(texts)
    if not texts:
        raise ValueError("need at least one text")
    return model.generate((encoder or get_encoder()).encode(texts), num_frames)


# ------------------------------------------------------------------ the learned filling
# baseline (Table 3)
def load_filler(dataset="coma", checkpoint=None):
    """Load the shipped LSTM filler of a dataset (sha256 checked)."""
    data.check_dataset_name(dataset)
    model, meta = load_checkpoint(
        checkpoint or checkpoint_name("lstm_filler", dataset),
        "lstm_filler",
        lambda c: lstm_filler.LSTMFiller(lstm_filler.LSTMFillerConfig(**c)),
    )
    model.normalizer, model.meta = (
        data.LandmarkNormalizer.from_dict(meta["normalizer"]),
        meta,
    )
    return model.eval()


@torch.no_grad()
def lstm_fill(sequences, known, filler=None, dataset="coma", seed=0):
    """Fill the unknown frames with the LSTM filler; (n, F, 68, 3) float32 mm, known
    frames kept exactly."""
    x, mask = check_fill_input(sequences, known)
    filler = filler or load_filler(dataset)
    xn = torch.as_tensor(filler.normalizer.normalize(x))
    out = filler.normalizer.denormalize(
        filler(xn, torch.as_tensor(mask), generator=torch.Generator().manual_seed(seed))
    )
    return keep_known(out.numpy(), x, mask)

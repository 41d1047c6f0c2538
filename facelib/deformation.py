"""Landmark-guided mesh deformation as a task (paper §3.3, §6, Table 5; the mesh-deformation and end-to-end chapters).

Training pairs come from the synthetic CoMA-like world, where every landmark sequence has its
ground-truth meshes: for sequence i and frame f, the input is the subject's neutral mesh M and
Delta L_f = L_f - L (the *captured* landmarks, with their noise, minus the neutral ones) and the
target is Delta M_f = M_f - M.

The two splits of §6 ("either 3 expressions or 3 subjects have been excluded from the training
set"):

* "identity": train on the training subjects, test on the 3 held-out subjects (the dataset's own
  train/test split);
* "expression": train on the training subjects without :data:`HELD_OUT_EXPRESSIONS`, test on
  those 3 expressions of the same subjects (the paper does not name its three; ours are one
  smile, one jaw opening and one asymmetric motion, each with relatives left in training).

Methods (Table 5 rows): "ours", "no_attention" (ours with F_e averaged instead of attended),
"s2d" (the decoder alone, from Delta L_f), "coma" (Chebyshev convolutions with pooling, its decoder
fed [code of M, Delta L_f]) and "linear" (Casas & Otaduy-style dense autoencoder, likewise).
Checkpoints are ``deform_<method>_<split>``; :func:`deform` uses ``deform_ours_identity``.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np
import torch

from . import data, metrics
from .config import DEFORMATION_DATASET as DATASET, HELD_OUT_EXPRESSIONS
from .checkpoints import checkpoint_paths, load_checkpoint
from .face import template as tpl
from .face.template import check_neutral_mesh
from .models import coma, deformer, linear_deformer

SPLITS = ("identity", "expression")
METHODS = {  # Table 5 row -> (model module, model config)
    "ours": (deformer, deformer.DeformerConfig()),
    "no_attention": (deformer, deformer.DeformerConfig(attention=False)),
    "s2d": (deformer, deformer.DeformerConfig(identity=False)),
    "coma": (coma, coma.ComaDeformerConfig()),
    "linear": (linear_deformer, linear_deformer.LinearDeformerConfig()),
}
METHOD_NAMES = {"ours": "Ours", "no_attention": "Ours (w/o attention)", "s2d": "S2D", "coma": "CoMA",
                "linear": "Linear"}


def check_split(split):
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; allowed: {', '.join(SPLITS)}")
    return split


def check_method(method):
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; allowed: {', '.join(METHODS)}")
    return method


def split_datasets(split):
    """(train, test) FaceDatasets of a split of §6 (see the module docstring)."""
    check_split(split)
    train = data.load_dataset(DATASET, "train")
    if split == "identity":
        return train, data.load_dataset(DATASET, "test")
    return data.expression_split(train, HELD_OUT_EXPRESSIONS)


@dataclass
class Pairs:
    """Deformation examples: K frames of each of n sequences, all in mm (float32)."""

    neutral: np.ndarray  # (n, V, 3) the subject's neutral mesh M
    delta_landmarks: np.ndarray  # (n, K, 68, 3) Delta L_f
    delta_mesh: np.ndarray  # (n, K, V, 3) Delta M_f, the target
    frames: np.ndarray  # (n, K) which frames of the sequence
    labels: np.ndarray  # (n,)

    def __len__(self):
        return len(self.neutral)


def make_pairs(dataset, frames_per_sequence=10, seed=None):
    """Pairs of every sequence of ``dataset``: ``frames_per_sequence`` frames, evenly spaced when
    ``seed`` is None (evaluation), else drawn at random without replacement (training)."""
    rng = None if seed is None else np.random.default_rng(seed)
    delta_l = dataset.delta_landmarks()
    neutral, dl, dm, frames = [], [], [], []
    for i in range(len(dataset)):
        length = int(dataset.lengths[i])
        k = min(frames_per_sequence, length)
        f = (np.linspace(0, length - 1, k).round().astype(int) if rng is None
             else np.sort(rng.choice(length, k, replace=False)))
        face = dataset.face(int(dataset.subjects[i]))
        m = face.neutral.astype(np.float32)
        neutral.append(m)
        dl.append(delta_l[i, f])
        dm.append(face.expression(dataset.au_weights[i, f].astype(np.float64)).astype(np.float32) - m)
        frames.append(f)
    return Pairs(np.stack(neutral), np.stack(dl), np.stack(dm), np.stack(frames), dataset.labels.copy())


def build_model(method):
    """A freshly initialised network of a Table 5 method."""
    module, model_config = METHODS[check_method(method)]
    return module.build(asdict(model_config))


def loss_weights():
    """S2D's per-vertex weights on the template (models/deformer.landmark_weights)."""
    t = tpl.get_template()
    return torch.as_tensor(deformer.landmark_weights(t.vertices, t.landmark_index))


def checkpoint_name(method, split):
    return f"deform_{check_method(method)}_{check_split(split)}"


def load_deformer(method="ours", split="identity", checkpoint=None):
    """Load a shipped deformation network (sha256 checked); ``model.meta`` holds its metadata."""
    name = checkpoint or checkpoint_name(method, split)
    module = METHODS[check_method(method)][0]
    _, js = checkpoint_paths(name)
    held = json.loads(js.read_text()).get("method") if js.exists() else method  # (missing: load_checkpoint says so)
    if held != method:  # before building: another method's config may not even build
        raise ValueError(f"checkpoint {name} holds method {held!r}, not {method!r}")
    model, meta = load_checkpoint(name, "deformer", module.build)
    model.meta = meta
    return model


def predict(model, pairs, batch_sequences=8):
    """Delta M (n, K, V, 3) predicted for every pair, without gradients."""
    out = []
    with torch.no_grad():
        for s in range(0, len(pairs), batch_sequences):
            sl = slice(s, s + batch_sequences)
            out.append(model(torch.as_tensor(pairs.neutral[sl]), torch.as_tensor(pairs.delta_landmarks[sl])).numpy())
    return np.concatenate(out)


def evaluate(model, pairs, batch_sequences=8):
    """Per-vertex Euclidean error of a model on pairs (Table 5's measure), in mm: see :func:`error_summary`."""
    return error_summary(np.linalg.norm(predict(model, pairs, batch_sequences) - pairs.delta_mesh, axis=-1), pairs)


def error_summary(errors, pairs):
    """Table 5's numbers from per-vertex errors (n, K, V) in mm: the mean and std over every (sequence,
    frame, vertex), a 95 % bootstrap interval of the mean over the test sequences ("ci"), the mean per
    vertex (V,) and per label, and the errors themselves."""
    per_label = {int(y): float(errors[pairs.labels == y].mean()) for y in np.unique(pairs.labels)}
    ci = metrics.bootstrap_interval(np.mean, errors.mean((1, 2))) if len(errors) > 1 else (np.nan, np.nan)
    return {"mean": float(errors.mean()), "std": float(errors.std()), "ci": ci, "per_vertex": errors.mean((0, 1)),
            "per_label": per_label, "errors": errors}


def check_landmark_sequence(landmarks):
    """A landmark sequence as float32 (F, 68, 3) in mm, or a clear error."""
    x = np.asarray(landmarks)
    if x.ndim != 3 or x.shape[1:] != (68, 3) or x.shape[0] < 1:
        raise ValueError(f"a landmark sequence must be (F, 68, 3) in mm, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("the landmark sequence contains NaN or infinite values")
    return x.astype(np.float32)


def deform(neutral_vertices, landmark_sequence, model=None):
    """Animate a neutral mesh (V, 3) of the template topology with a landmark sequence (F, 68, 3),
    both in mm: Delta L_f = L_f - L with L the neutral mesh's own landmarks, M_f = M + Delta M_f.
    The mouth-interior rows are then re-placed between the inner lips, as the face world builds
    them (face/template.place_mouth_band): they are not skin the network should have to predict,
    and outside the mouth they coincide, so any error between them would show as a crease.
    Returns the meshes (F, V, 3) float32 in mm."""
    neutral = check_neutral_mesh(neutral_vertices)
    landmarks = check_landmark_sequence(landmark_sequence)
    model = model or load_deformer()
    delta = landmarks - neutral[tpl.get_template().landmark_index]
    with torch.no_grad():
        dm = model(torch.as_tensor(neutral)[None], torch.as_tensor(delta)[None])[0].numpy()
    return tpl.place_mouth_band(neutral[None] + dm, tpl.get_template())

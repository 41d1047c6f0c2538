"""Landmark-guided mesh deformation as a task (paper §3.3, §6, Table 5; the
mesh-deformation and end-to-end chapters).

Training pairs come from the synthetic CoMA-like world, where every landmark sequence
has its ground-truth meshes: for sequence i and frame f, the input is the subject's
neutral mesh M and Delta L_f = L_f - L (the *captured* landmarks, with their noise,
minus the neutral ones) and the target is Delta M_f = M_f - M.

The two splits of §6 ("either 3 expressions or 3 subjects have been excluded from the
training set"):

* "identity": train on the training subjects, test on the 3 held-out subjects (the
  dataset's own train/test split);
* "expression": train on the training subjects without :data:`HELD_OUT_EXPRESSIONS`,
  test on those 3 expressions of the same subjects (the paper does not name its three;
  ours are one smile, one jaw opening and one asymmetric motion, each with relatives
  left in training).

Methods (Table 5 rows): "ours", "no_attention" (ours with F_e averaged instead of
attended), "s2d" (the decoder alone, from Delta L_f), "coma" (Chebyshev convolutions
with pooling, its decoder fed [code of M, Delta L_f]) and "linear" (Casas & Otaduy-style
dense autoencoder, likewise). Checkpoints are ``deform_<method>_<split>``;
:func:`deform` uses ``deform_ours_identity``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np
import torch

from . import data, metrics
from .config import DEFORMATION_DATASET as DATASET, HELD_OUT_EXPRESSIONS
from .checkpoints import checkpoint_name, checkpoint_paths, load_checkpoint
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
METHOD_NAMES = {
    "ours": "Ours",
    "no_attention": "Ours (w/o attention)",
    "s2d": "S2D",
    "coma": "CoMA",
    "linear": "Linear",
}


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
    subjects: np.ndarray  # (n,) the dataset's subject of each sequence (its face)

    def __len__(self):
        return len(self.neutral)

    def noise_free(self):
        """The same pairs with the world's exact Delta L_f instead of the captured one:
        the landmarks are vertices of the mesh, so it is Delta M_f at the template's
        landmark vertices."""
        exact = self.delta_mesh[:, :, tpl.get_template().landmark_index]
        return Pairs(
            self.neutral,
            exact,
            self.delta_mesh,
            self.frames,
            self.labels,
            self.subjects,
        )


def make_pairs(dataset, frames_per_sequence=10, seed=None, noise_free=False):
    """Pairs of every sequence of ``dataset``: ``frames_per_sequence`` frames, evenly
    spaced when ``seed`` is None (evaluation), else drawn at random without replacement
    (training). ``noise_free``: Delta L_f from the world's exact landmarks instead of
    the captured (noisy) ones (:meth:`Pairs.noise_free` gives the same from pairs
    already made)."""
    rng = None if seed is None else np.random.default_rng(seed)
    delta_l = dataset.delta_landmarks() if not noise_free else None
    neutral, dl, dm, frames = [], [], [], []
    for i in range(len(dataset)):
        length = int(dataset.lengths[i])
        k = min(frames_per_sequence, length)
        f = (
            np.linspace(0, length - 1, k).round().astype(int)
            if rng is None
            else np.sort(rng.choice(length, k, replace=False))
        )
        face = dataset.face(int(dataset.subjects[i]))
        m = face.neutral.astype(np.float32)
        neutral.append(m)
        dm.append(
            face.expression(dataset.au_weights[i, f].astype(np.float64)).astype(
                np.float32
            )
            - m
        )
        # the landmarks are vertices of the mesh: the exact Delta L_f is Delta M_f at
        # the landmark vertices
        dl.append(
            dm[-1][:, tpl.get_template().landmark_index]
            if noise_free
            else delta_l[i, f]
        )
        frames.append(f)
    return Pairs(
        np.stack(neutral),
        np.stack(dl),
        np.stack(dm),
        np.stack(frames),
        dataset.labels.copy(),
        dataset.subjects.copy(),
    )


def build_model(method):
    """A freshly initialised network of a Table 5 method."""
    module, model_config = METHODS[check_method(method)]
    return module.build(asdict(model_config))


def loss_weights():
    """S2D's per-vertex weights on the template (models/deformer.landmark_weights)."""
    t = tpl.get_template()
    return torch.as_tensor(deformer.landmark_weights(t.vertices, t.landmark_index))


def deformer_checkpoint(method, split, seed=0):
    """The name of the deformer checkpoint of a Table 5 row (method) and split
    (checkpoints.checkpoint_name)."""
    return checkpoint_name("deform", check_method(method), check_split(split), seed)


def load_deformer(method="ours", split="identity", checkpoint=None):
    """Load a shipped deformation network (sha256 checked); ``model.meta`` holds its
    metadata."""
    name = checkpoint or deformer_checkpoint(method, split)
    module = METHODS[check_method(method)][0]
    _, js = checkpoint_paths(name)
    # (missing: load_checkpoint says so)
    held = json.loads(js.read_text()).get("method") if js.exists() else method
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
            out.append(
                model(
                    torch.as_tensor(pairs.neutral[sl]),
                    torch.as_tensor(pairs.delta_landmarks[sl]),
                ).numpy()
            )
    return np.concatenate(out)


def evaluate(model, pairs, batch_sequences=8):
    """Per-vertex Euclidean error of a model on pairs (Table 5's measure), in mm: see
    :func:`error_summary`."""
    return error_summary(
        np.linalg.norm(
            predict(model, pairs, batch_sequences) - pairs.delta_mesh, axis=-1
        ),
        pairs,
    )


def error_summary(errors, pairs):
    """Table 5's numbers from per-vertex errors (n, K, V) in mm: the mean and std over
    every (sequence, frame, vertex), a 95 % bootstrap interval of the mean over the test
    sequences ("ci"), the mean per vertex (V,) and per label, and the errors
    themselves."""
    per_label = {
        int(y): float(errors[pairs.labels == y].mean()) for y in np.unique(pairs.labels)
    }
    ci = (
        metrics.bootstrap_interval(np.mean, errors.mean((1, 2)))
        if len(errors) > 1
        else (np.nan, np.nan)
    )
    return {
        "mean": float(errors.mean()),
        "std": float(errors.std()),
        "ci": ci,
        "per_vertex": errors.mean((0, 1)),
        "per_label": per_label,
        "errors": errors,
    }


def check_landmark_sequence(landmarks):
    """A landmark sequence as float32 (F, 68, 3) in mm, or a clear error."""
    x = np.asarray(landmarks)
    if x.ndim != 3 or x.shape[1:] != (68, 3) or x.shape[0] < 1:
        raise ValueError(
            f"a landmark sequence must be (F, 68, 3) in mm, got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError("the landmark sequence contains NaN or infinite values")
    return x.astype(np.float32)


def deform(neutral_vertices, landmark_sequence, model=None):
    """Animate a neutral mesh (V, 3) of the template topology with a landmark sequence
    (F, 68, 3), both in mm: Delta L_f = L_f - L with L the neutral mesh's own landmarks,
    M_f = M + Delta M_f.  The mouth-interior rows are then re-placed between the inner
    lips, as the face world builds them (face/template.place_mouth_band): they are not
    skin the network should have to predict, and outside the mouth they coincide, so any
    error between them would show as a crease.  Returns the meshes (F, V, 3) float32 in
    mm."""
    neutral = check_neutral_mesh(neutral_vertices)
    landmarks = check_landmark_sequence(landmark_sequence)
    model = model or load_deformer()
    delta = landmarks - neutral[tpl.get_template().landmark_index]
    with torch.no_grad():
        dm = model(torch.as_tensor(neutral)[None], torch.as_tensor(delta)[None])[
            0
        ].numpy()
    return tpl.place_mouth_band(neutral[None] + dm, tpl.get_template())


def motion_features(pairs):
    """[Delta L_f, 1] of every pair frame, (n K, 205) float32: the inputs of the
    closed-form regression."""
    x = pairs.delta_landmarks.reshape(-1, 204)
    return np.hstack([x, np.ones((len(x), 1), np.float32)])


def identity_features(pairs, identity_coeffs, reference):
    """[Delta L_f, 1] and its interactions with the face's identity coefficients, (n K,
    205 (1 + c)) float32: a regression on them can change its map from Delta L_f to
    Delta M_f with the face.  ``identity_coeffs`` (n, c): each pair's face;
    ``reference`` (m, c): the training faces, whose mean and std standardise them.
    """
    reference = np.asarray(reference, dtype=np.float64)
    c = (np.asarray(identity_coeffs) - reference.mean(0)) / reference.std(0)
    x = motion_features(pairs).reshape(len(pairs), -1, 205)
    interactions = (x[..., :, None] * c[:, None, None, :].astype(np.float32)).reshape(
        *x.shape[:2], -1
    )
    return np.concatenate([x, interactions], -1).reshape(-1, 205 * (1 + c.shape[1]))


def fit_linear_regression(pairs, penalty=1e-2, features=None):
    """The closed-form reference row of Table 5: the ridge regression Delta M_f ~ A
    Delta L_f + b over every training pair frame, one map for every face (``penalty`` on
    every coefficient, b included: it is tiny against the normal equations' scale).
    ``features``: other inputs than :func:`motion_features` (e.g.
    :func:`identity_features`).  X^T X is formed in float64, X^T Y in float32 to keep
    the (n K, V 3) targets in memory.  Returns the coefficients (d, V 3).
    """
    x = (motion_features(pairs) if features is None else features).astype(np.float64)
    y = pairs.delta_mesh.reshape(len(x), -1)
    return np.linalg.solve(
        x.T @ x + penalty * np.eye(x.shape[1]),
        (x.T.astype(np.float32) @ y).astype(np.float64),
    )


def linear_regression_errors(coefficients, pairs, features=None):
    """Per-vertex Euclidean errors (n, K, V) in mm of :func:`fit_linear_regression`'s
    map on ``pairs`` (``features``: the same kind of inputs it was fitted on)."""
    x = motion_features(pairs) if features is None else features
    predicted = (x @ coefficients.astype(np.float32)).reshape(pairs.delta_mesh.shape)
    return np.linalg.norm(predicted - pairs.delta_mesh, axis=-1)


def attention_weights(model, pairs, batch_sequences=8):
    """The attention weights of Eq. 11 over the coarse vertices for every pair frame,
    (n, K, num_coarse): where on the face "ours" looks for each landmark motion (each
    row sums to 1)."""
    if not (model.config.attention and model.config.identity):
        raise ValueError(
            "this deformer does not attend to the face: 'ours without attention'"
            " averages F_e, S2D never reads the mesh; only 'ours' has Eq. 11's"
            " attention"
        )
    out = []
    with torch.no_grad():
        for s in range(0, len(pairs), batch_sequences):
            sl = slice(s, s + batch_sequences)
            features = model.encode(torch.as_tensor(pairs.neutral[sl]))
            _, w = model.attend(
                features,
                torch.as_tensor(pairs.delta_landmarks[sl]) / model.config.scale,
            )
            out.append(w.numpy())
    return np.concatenate(out)


def attention_entropy(model, pairs, batch_sequences=8):
    """Entropy (nats) of the attention weights of Eq. 11 for every pair frame, (n, K);
    uniform weights over the coarse vertices give log(num_coarse), one vertex only gives
    0."""
    w = attention_weights(model, pairs, batch_sequences).astype(np.float64)
    return -(w * np.log(np.clip(w, 1e-30, None))).sum(-1)


def per_face(errors, subjects):
    """Mean error per test face: (faces (m,), means (m,)) from per-vertex errors (n, K,
    V) and the subject (n,) of each pair."""
    faces = np.unique(subjects)
    return faces, np.array([errors[subjects == f].mean() for f in faces])


def paired_difference(errors, reference, subjects, num_resamples=1000, seed=0):
    """Mean error of ``errors`` minus that of ``reference`` (both (n, K, V) on the same
    pairs) with a 95 % bootstrap interval over the test faces, resampled together
    (paired): (difference, (low, high)).
    """
    _, a = per_face(errors, subjects)
    _, b = per_face(reference, subjects)
    diff = a - b
    return float(diff.mean()), metrics.bootstrap_interval(
        np.mean, diff, num_resamples=num_resamples, seed=seed
    )


def over_seeds(means):
    """A Table 5 cell over training seeds: (mean, std with ddof 1; 0 for a single seed)
    of the seeds' means."""
    m = np.asarray(means, dtype=np.float64)
    return float(m.mean()), float(m.std(ddof=1)) if len(m) > 1 else 0.0

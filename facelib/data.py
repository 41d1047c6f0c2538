"""Synthetic datasets: generation, cache with checksums, splits (paper §4, DESIGN.md).

``load_dataset("coma" | "bu" | "coma+bu", "train" | "test" | "all", num_frames=40)``
returns a :class:`FaceDataset` of landmark sequences (n, F, 68, 3) float32 in mm with
integer labels, N2E/E2N kinds and subject ids; each subject's neutral mesh and every
frame's mesh are available on demand.  Datasets are generated deterministically on first
use and cached under ``data/synthetic/cache`` (the file name carries a hash of the
generator's source and configuration, so a changed generator never reuses a stale
cache).  Each cache file has a sha256 sidecar; a file whose checksum does not match is
rebuilt with a warning. "coma+bu" is not generated: it is the union of the two (paper
§5.2, text control: 18 actions).
"""

from __future__ import annotations

import ast
import hashlib
import json
import warnings
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from . import config
from .files import atomic_write, atomic_write_text
from .face import aus, expressions, sequences
from .face.aus import AU_NAMES, Face
from .face.expressions import BU_LABELS, COMA_LABELS, KIND_NAMES
from .face.identity import IDENTITY_MODES, sample_identity
from .face.sequences import Timing, check_num_frames

LABEL_SETS = {"coma": COMA_LABELS, "bu": BU_LABELS}
TIMING = Timing()
# our choice: per-take variation of the whole expression's intensity
APEX_SCALE = (0.75, 1.1)
_SOURCE_FILES = (
    "face/template.py",
    "face/identity.py",
    "face/aus.py",
    "face/tissue.py",
    "face/expressions.py",
    "face/sequences.py",
    "data.py",
)


# paper §5.2: "merging CoMA and BU-4DFE" (18 actions)
MERGED_DATASETS = {"coma+bu": ("coma", "bu"), "coma+crowd": ("coma", "coma_crowd")}
DATASET_NAMES = (*config.DATASETS, *MERGED_DATASETS)
# the datasets a model is trained or sampled on (the settings' choices)
# (not the evaluation-only ones, nor a part without test people, such as coma_crowd)
MODEL_DATASETS = tuple(
    n
    for n in DATASET_NAMES
    if n not in config.EVALUATION_DATASETS
    and (n in MERGED_DATASETS or config.DATASETS[n].num_test_subjects > 0)
)


def check_dataset_name(name):
    """The name of a loadable dataset (generated or merged); a clear error listing them
    if unknown."""
    if name not in DATASET_NAMES:
        raise ValueError(
            f"unknown dataset {name!r}; allowed: {', '.join(DATASET_NAMES)}"
        )
    return name


def generated_spec(name):
    """The :class:`~facelib.config.DatasetSpec` of a generated dataset (merged ones have
    none)."""
    if check_dataset_name(name) not in config.DATASETS:
        raise ValueError(
            f"dataset {name!r} is not generated but merged from"
            f" {MERGED_DATASETS[name]}; generated datasets:"
            f" {', '.join(config.DATASETS)}"
        )
    return config.DATASETS[name]


# paper §5: order-Insensitive (label), order-Sensitive (label x N2E/E2N)
CLASSIFIER_TYPES = ("I", "S")


def check_classifier_type(classifier_type):
    if classifier_type not in CLASSIFIER_TYPES:
        raise ValueError(
            f"classifier type must be one of {CLASSIFIER_TYPES} (I: label, S: label x"
            f" N2E/E2N), got {classifier_type!r}"
        )


def neutral_frame_indices(kinds, num_frames):
    """The frame of each sequence that shows the neutral face: 0 for N2E, the last
    (num_frames - 1) for E2N (``kinds`` index KIND_NAMES, as FaceDataset.kinds do)."""
    kinds = np.asarray(kinds)
    if not np.isin(kinds, range(len(KIND_NAMES))).all():
        raise ValueError(
            f"kinds must index {KIND_NAMES} (0 or 1), got {sorted(set(kinds.tolist()))}"
        )
    return np.where(kinds == KIND_NAMES.index("N2E"), 0, num_frames - 1)


def check_split(split):
    if split not in config.SPLITS:
        raise ValueError(
            f"unknown split {split!r}; allowed: {', '.join(config.SPLITS)}"
        )
    return split


def _check_length(num_frames):
    """An int (fixed length) or a (low, high) pair (each sequence's length uniform in
    it)."""
    if isinstance(num_frames, (tuple, list)):
        if len(num_frames) != 2:
            raise ValueError(
                f"a variable length must be a (low, high) pair, got {num_frames!r}"
            )
        lo, hi = (check_num_frames(v) for v in num_frames)
        if lo > hi:
            raise ValueError(f"variable length range has low > high: {num_frames!r}")
        return (lo, hi)
    return check_num_frames(num_frames)


def generator_fingerprint(spec, num_frames):
    """Hash of everything that determines a dataset: spec, length, timing, the
    generator's code (its syntax tree without docstrings, so that a comment or a line
    break does not invalidate the cache) and the config values it reads."""
    h = hashlib.sha256()
    h.update(
        json.dumps(
            [config.WORLD, asdict(spec), num_frames, asdict(TIMING), APEX_SCALE],
            sort_keys=True,
        ).encode()
    )
    root = Path(__file__).parent
    sources = [(root / rel).read_text() for rel in _SOURCE_FILES]
    for source in sources:
        h.update(_code_of(source).encode())
    h.update(repr(_config_read_by(sources)).encode())
    return h.hexdigest()[:12]


def _config_read_by(sources):
    """The values of the facelib/config.py names that the generator's ``sources``
    read (``from ..config import X``, ``config.X``), by name: a change elsewhere in
    config.py (a guidance constant) leaves the caches valid.  Paths and functions say
    where the caches go, not what they hold, and are left out."""
    names = set()
    for node in (n for source in sources for n in ast.walk(ast.parse(source))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("config"):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id == "config":
                names.add(node.attr)
    values = {n: getattr(config, n) for n in sorted(names)}
    return {
        n: v for n, v in values.items() if not callable(v) and not isinstance(v, Path)
    }


def _code_of(source):
    """The syntax tree of ``source`` without its docstrings, as text."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (
            isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef))
            and body
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)
        ):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def _sequence_plan(spec):
    """(subject, label, take, kind) of every sequence, in a fixed order."""
    labels = LABEL_SETS[spec.label_set]
    pairs = [(s, l) for s in range(spec.num_subjects) for l in range(len(labels))]
    base = len(pairs) * spec.takes_per_pair
    extra = spec.num_sequences - base
    if not 0 <= extra <= len(pairs):
        raise ValueError(
            f"dataset {spec.name}: cannot make {spec.num_sequences} sequences from "
            f"{len(pairs)} pairs x {spec.takes_per_pair} takes"
        )
    rng = np.random.default_rng([spec.seed, 99])
    extra_pairs = set(rng.choice(len(pairs), size=extra, replace=False).tolist())
    plan = []
    for p, (s, l) in enumerate(pairs):
        takes = spec.takes_per_pair + (p in extra_pairs)
        for k in range(takes):
            kind = k % 2 if k < spec.takes_per_pair else int(rng.integers(2))
            plan.append((s, l, spec.first_take + k, kind))
    return plan


def identity_coefficients(spec):
    """Identity coefficients (num_subjects, 14) of the subjects of a dataset."""
    return np.stack(
        [
            sample_identity(np.random.default_rng([spec.seed, 0, s]))
            for s in range(spec.num_subjects)
        ]
    )


def test_subjects(spec):
    """The subjects held out for the test split (sorted)."""
    rng = np.random.default_rng([spec.seed, 7])
    return np.sort(rng.permutation(spec.num_subjects)[: spec.num_test_subjects])


def _play(face, apex, kind, num_frames, rng):
    """One performance of AU apex intensities as a ``kind`` sequence on ``face``:
    landmarks (F, 68, 3) in mm with the world's timing and capture noise, and the AU
    curves (F, NUM_AUS) that made it.
    """
    w = sequences.au_curves(apex, kind, num_frames, rng, TIMING)
    return face.landmarks(w) + TIMING.noise_mm * rng.standard_normal((len(w), 68, 3)), w


def generate(spec, num_frames=40):
    """Generate all sequences of a dataset (both splits) as a dict of arrays
    (deterministic)."""
    num_frames = _check_length(num_frames)
    labels = LABEL_SETS[spec.label_set]
    coeffs = identity_coefficients(spec)
    plan = _sequence_plan(spec)
    lengths = np.array(
        [
            (
                num_frames
                if isinstance(num_frames, int)
                else int(
                    np.random.default_rng([spec.seed, 5, s, l, t]).integers(
                        num_frames[0], num_frames[1] + 1
                    )
                )
            )
            for s, l, t, _ in plan
        ]
    )
    fmax = int(lengths.max())
    n = len(plan)
    landmarks = np.zeros((n, fmax, 68, 3), np.float32)
    weights = np.zeros((n, fmax, aus.NUM_AUS), np.float32)
    spread = expressions.StyleSpread(
        spec.style_gain_sigma,
        spec.style_leak_probability,
        spec.style_leak_max,
        spec.style_blend_max,
    )
    face, style = None, None
    # the plan is ordered by subject, then label
    for i, (s, l, take, kind) in enumerate(plan):
        if face is None or plan[i - 1][0] != s:
            face = Face(coeffs[s])
        if take == spec.first_take:
            style = expressions.sample_style(
                labels[l], np.random.default_rng([spec.seed, 1, s, l]), spread, labels
            )
        rng = np.random.default_rng([spec.seed, 2, s, l, take])
        apex = expressions.apex_intensities(
            labels[l], style, rng, scale=rng.uniform(*APEX_SCALE)
        )
        landmarks[i, : lengths[i]], weights[i, : lengths[i]] = _play(
            face, apex, KIND_NAMES[kind], int(lengths[i]), rng
        )
    plan = np.array(plan)
    return {
        "landmarks": landmarks,
        "au_weights": weights,
        "lengths": lengths.astype(np.int64),
        "subjects": plan[:, 0].astype(np.int64),
        "labels": plan[:, 1].astype(np.int64),
        "takes": plan[:, 2].astype(np.int64),
        "kinds": plan[:, 3].astype(np.int8),
        "identity_coeffs": coeffs,
        "test_subjects": test_subjects(spec),
    }


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def cache_path(name, num_frames=40, cache_dir=None):
    spec = generated_spec(name)
    num_frames = _check_length(num_frames)
    tag = (
        f"F{num_frames}"
        if isinstance(num_frames, int)
        else f"F{num_frames[0]}-{num_frames[1]}"
    )
    fingerprint = generator_fingerprint(spec, num_frames)
    return (
        Path(cache_dir or config.cache_dir())
        / f"{name}-world{config.WORLD}-{tag}-{fingerprint}.npz"
    )


def _read_verified(path):
    """Arrays of a cache file if its checksum matches its sidecar; None (with a warning)
    if not."""
    sidecar = path.with_suffix(".sha256")
    if not path.exists():
        return None
    expected = sidecar.read_text().strip() if sidecar.exists() else None
    actual = _sha256(path)
    if expected != actual:
        warnings.warn(
            f"cache file {path.name} is corrupted or incomplete (sha256 {actual[:12]}"
            f" does not match its checksum {str(expected)[:12]}); rebuilding it",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def build(name, num_frames=40, cache_dir=None, rebuild=False):
    """Arrays of the whole dataset: read from the verified cache, or generated and
    cached."""
    spec = generated_spec(name)
    path = cache_path(name, num_frames, cache_dir)
    arrays = None if rebuild else _read_verified(path)
    if arrays is None:
        arrays = generate(spec, _check_length(num_frames))
        atomic_write(path, lambda f: np.savez(f, **arrays))
        atomic_write_text(path.with_suffix(".sha256"), _sha256(path) + "\n")
        _remove_stale(path)
    return arrays


def _remove_stale(path):
    """Delete caches of the same dataset and length made by an older generator."""
    prefix = path.stem.rsplit("-", 1)[0] + "-"
    for old in path.parent.glob(prefix + "*"):
        if (
            old.stem != path.stem
            and old.suffix in (".npz", ".sha256")
            and old.stem.rsplit("-", 1)[0] + "-" == prefix
        ):
            old.unlink(missing_ok=True)


@lru_cache(maxsize=256)
def _face(coeffs_bytes):
    return Face(np.frombuffer(coeffs_bytes, dtype=np.float64).copy())


@dataclass
class FaceDataset:
    """Landmark sequences of one split of a synthetic dataset.

    ``landmarks[i, :lengths[i]]`` is sequence i, (F, 68, 3) float32 in mm (with capture
    noise); frames beyond ``lengths[i]`` (variable-length datasets only) are zero.
    ``labels[i]`` indexes ``label_names``; ``kinds[i]`` indexes ``KIND_NAMES`` ("N2E",
    "E2N"); ``subjects[i]`` is the dataset's subject id (0 .. num_subjects-1), whose
    identity coefficients are ``identity_coeffs[subjects[i]]``; ``au_weights[i]`` are
    the AU intensity curves that made it.
    """

    name: str
    split: str
    landmarks: np.ndarray
    labels: np.ndarray
    kinds: np.ndarray
    subjects: np.ndarray
    lengths: np.ndarray
    au_weights: np.ndarray
    identity_coeffs: np.ndarray
    label_names: tuple
    kind_names: tuple = KIND_NAMES
    au_names: tuple = AU_NAMES
    extra: dict = field(default_factory=dict, repr=False)

    def __len__(self):
        return len(self.labels)

    def __repr__(self):
        return (
            f"FaceDataset({self.name!r}, split={self.split!r}, n={len(self)},"
            f" frames={self.landmarks.shape[1]},"
            f" subjects={len(np.unique(self.subjects))},"
            f" labels={len(self.label_names)})"
        )

    @property
    def num_frames(self):
        return self.landmarks.shape[1]

    @property
    def faces(self):
        """Triangles (K, 3) of every mesh of the world (fixed topology)."""
        return aus.tpl.get_template().faces

    def face(self, subject):
        """The :class:`Face` (identity) of a subject of this dataset."""
        if not 0 <= subject < len(self.identity_coeffs):
            raise ValueError(
                f"subject must be in [0, {len(self.identity_coeffs)}), got {subject}"
            )
        return _face(
            np.ascontiguousarray(
                self.identity_coeffs[subject], dtype=np.float64
            ).tobytes()
        )

    def neutral_mesh(self, subject):
        """Neutral vertices (V, 3) in mm of a subject."""
        return self.face(subject).neutral.astype(np.float32)

    def neutral_landmarks(self, subject):
        """The 68 neutral landmarks (68, 3) in mm of a subject (noise-free)."""
        return self.face(subject).landmarks(np.zeros(aus.NUM_AUS)).astype(np.float32)

    def sequence_neutrals(self):
        """The neutral landmarks (n, 68, 3) in mm of the subject of every sequence."""
        neutral = {s: self.neutral_landmarks(int(s)) for s in np.unique(self.subjects)}
        return np.stack([neutral[s] for s in self.subjects])

    def delta_landmarks(self):
        """Delta L_f = L_f - L (paper §3.3): every sequence minus its subject's neutral
        landmarks, (n, F, 68, 3)."""
        valid = (np.arange(self.landmarks.shape[1])[None, :] < self.lengths[:, None])[
            ..., None, None
        ]
        return ((self.landmarks - self.sequence_neutrals()[:, None]) * valid).astype(
            np.float32
        )

    def subject_neutrals(self):
        """Neutral landmarks (K, 68, 3) of the K subjects of this split (sorted by
        subject id)."""
        return np.stack(
            [self.neutral_landmarks(int(s)) for s in np.unique(self.subjects)]
        )

    def meshes(self, i):
        """Per-frame meshes (F, V, 3) float32 in mm of sequence i (noise-free;
        landmarks[i] adds noise)."""
        if not 0 <= i < len(self):
            raise ValueError(f"sequence index must be in [0, {len(self)}), got {i}")
        w = self.au_weights[i, : self.lengths[i]].astype(np.float64)
        return self.face(int(self.subjects[i])).expression(w).astype(np.float32)

    def label_of(self, i):
        return self.label_names[self.labels[i]]

    def class_names(self, classifier_type="I"):
        """Class names of a classifier of type "I" (the label: order-insensitive) or "S"
        (label x N2E/E2N: order-sensitive), as in paper §5."""
        check_classifier_type(classifier_type)
        if classifier_type == "I":
            return tuple(self.label_names)
        return tuple(
            f"{label} {kind}" for label in self.label_names for kind in self.kind_names
        )

    def targets(self, classifier_type="I"):
        """Class index (n,) of every sequence for a classifier of type "I" or "S" (see
        class_names)."""
        check_classifier_type(classifier_type)
        if classifier_type == "I":
            return self.labels.copy()
        return self.labels * len(self.kind_names) + self.kinds

    def subset(self, mask, split=None):
        """A new dataset with the sequences selected by a boolean mask or an index
        array."""
        sel = np.asarray(mask)
        return FaceDataset(
            self.name,
            split or self.split,
            self.landmarks[sel],
            self.labels[sel],
            self.kinds[sel],
            self.subjects[sel],
            self.lengths[sel],
            self.au_weights[sel],
            self.identity_coeffs,
            self.label_names,
            extra=self.extra,
        )


def load_dataset(name, split="train", num_frames=40, cache_dir=None, rebuild=False):
    """Load (generating and caching on first use) a split of a synthetic dataset.

    name: "coma" (12 CoMA-like labels, 12 subjects, 689 sequences), "bu" (6 emotions,
    101 subjects, 1212 sequences) or "coma+bu" (their union, 18 labels, 113 subjects:
    see :func:`merge`).  split: "train", "test" (held-out subjects) or "all".
    num_frames: an int in [2, 400] (40 in the paper) or a (low, high) range for variable
    lengths.
    """
    check_dataset_name(name)
    check_split(split)
    if name in MERGED_DATASETS:
        return merge(
            [
                load_dataset(part, split, num_frames, cache_dir, rebuild)
                for part in MERGED_DATASETS[name]
            ],
            name,
        )
    spec = generated_spec(name)
    arrays = build(name, num_frames, cache_dir, rebuild)
    held_out = np.isin(arrays["subjects"], arrays["test_subjects"])
    sel = {"train": ~held_out, "test": held_out, "all": np.ones_like(held_out)}[split]
    ds = FaceDataset(
        spec.name,
        "all",
        arrays["landmarks"],
        arrays["labels"],
        arrays["kinds"],
        arrays["subjects"],
        arrays["lengths"],
        arrays["au_weights"],
        arrays["identity_coeffs"],
        LABEL_SETS[spec.label_set],
        extra={"test_subjects": arrays["test_subjects"]},
    )
    return ds.subset(sel, split)


def merge(parts, name):
    """One dataset from several (paper §5.2): labels are the union in order (12
    CoMA-like then 6 emotions for "coma+bu"); subject ids of each part are offset by the
    subjects before it, so every subject keeps its own face; splits stay as they were
    (test subjects stay test).
    """
    if (
        len({p.split for p in parts}) != 1
        or len({p.landmarks.shape[1] for p in parts}) != 1
    ):
        raise ValueError(
            "datasets to merge must be the same split with the same number of frames"
        )
    if all(p.label_names == parts[0].label_names for p in parts):
        # more people performing the same labels
        names, label_offsets = tuple(parts[0].label_names), np.zeros(len(parts), int)
    else:
        names = tuple(label for p in parts for label in p.label_names)
        if len(set(names)) != len(names):
            raise ValueError(f"datasets to merge share some labels: {names}")
        label_offsets = np.cumsum([0] + [len(p.label_names) for p in parts])
    subject_offsets = np.cumsum([0] + [len(p.identity_coeffs) for p in parts])
    cat = lambda key: np.concatenate([getattr(p, key) for p in parts])
    return FaceDataset(
        name,
        parts[0].split,
        cat("landmarks"),
        np.concatenate([p.labels + o for p, o in zip(parts, label_offsets)]),
        cat("kinds"),
        np.concatenate([p.subjects + o for p, o in zip(parts, subject_offsets)]),
        cat("lengths"),
        cat("au_weights"),
        cat("identity_coeffs"),
        names,
        extra={
            "test_subjects": np.concatenate(
                [p.extra["test_subjects"] + o for p, o in zip(parts, subject_offsets)]
            )
        },
    )


def composed_performances(dataset, labels, kind="N2E", seed=0):
    """The synthetic world's own composition of expressions (the compositions of text
    control; no dataset holds one): for every subject of ``dataset`` (a FaceDataset),
    one performance of each label in ``labels`` (one or two names), combined as FACS
    combines action units, per AU the stronger of the performances (a per-AU maximum of
    the apex intensities), then played as one ``kind`` sequence with the world's timing
    and capture noise.  One label gives a plain performance.

    Returns landmarks (n, F, 68, 3) float32 in mm and the subject id (n,) of each
    sequence.
    """
    labels = (labels,) if isinstance(labels, str) else tuple(labels)
    if not 1 <= len(labels) <= 2:
        raise ValueError(f"labels must be one or two label names, got {labels!r}")
    for label in labels:
        if label not in dataset.label_names:
            raise ValueError(
                f"unknown label {label!r} for dataset {dataset.name!r}; allowed: "
                f"{', '.join(dataset.label_names)}"
            )
    if kind not in KIND_NAMES:
        raise ValueError(f"kind must be one of {KIND_NAMES}, got {kind!r}")
    subjects = np.unique(dataset.subjects)
    out = np.zeros((len(subjects), dataset.num_frames, 68, 3), np.float32)
    for i, s in enumerate(subjects):
        rng = np.random.default_rng([seed, 13, int(s)])
        apex = np.max(
            [
                expressions.apex_intensities(
                    label,
                    expressions.sample_style(label, rng),
                    rng,
                    scale=rng.uniform(*APEX_SCALE),
                )
                for label in labels
            ],
            0,
        )
        out[i] = _play(dataset.face(int(s)), apex, kind, dataset.num_frames, rng)[0]
    return out, subjects


def expression_split(dataset, held_out):
    """(train, test) subsets of ``dataset`` where the test part holds the labels in
    ``held_out``."""
    held_out = [held_out] if isinstance(held_out, str) else list(held_out)
    for label in held_out:
        if label not in dataset.label_names:
            raise ValueError(
                f"unknown label {label!r} for dataset {dataset.name!r}; "
                f"allowed: {', '.join(dataset.label_names)}"
            )
    test = np.isin(dataset.labels, [dataset.label_names.index(l) for l in held_out])
    return dataset.subset(~test, "expression-train"), dataset.subset(
        test, "expression-test"
    )


def fingerprint(arrays):
    """A summary that identifies a dataset: exact hash of its integer metadata, landmark
    statistics."""
    meta = hashlib.sha256()
    for k in ("labels", "kinds", "subjects", "takes", "lengths", "test_subjects"):
        meta.update(np.ascontiguousarray(arrays[k]).astype(np.int64).tobytes())
    lm = arrays["landmarks"].astype(np.float64)
    return {
        "num_sequences": int(len(arrays["labels"])),
        "metadata_sha256": meta.hexdigest(),
        "landmark_mean_mm": round(float(lm.mean()), 4),
        "landmark_std_mm": round(float(lm.std()), 4),
        "landmark_abs_mean_mm": round(float(np.abs(lm).mean()), 4),
    }


FINGERPRINT_FILE = config.SYNTHETIC_DIR / "fingerprints.json"
CONFIG_FILE = config.SYNTHETIC_DIR / "config.json"


def generator_config():
    """The configuration of every dataset as plain data (written to
    data/synthetic/config.json)."""
    return {
        "datasets": {n: asdict(s) for n, s in config.DATASETS.items()},
        "label_sets": {k: list(v) for k, v in LABEL_SETS.items()},
        "timing": asdict(TIMING),
        "apex_scale": list(APEX_SCALE),
        "action_units": list(AU_NAMES),
        "identity_modes": list(IDENTITY_MODES),
    }


def summary(name, arrays):
    """A printable summary of a whole dataset: counts per split, label, kind, subject;
    value ranges."""
    spec = generated_spec(name)
    labels = LABEL_SETS[spec.label_set]
    held_out = np.isin(arrays["subjects"], arrays["test_subjects"])
    lm = arrays["landmarks"]
    lines = [
        (
            f"dataset {name!r}: {len(arrays['labels'])} sequences, {spec.num_subjects}"
            f" subjects ({int((~held_out).sum())} train / {int(held_out.sum())} test"
            f" sequences; test subjects {arrays['test_subjects'].tolist()}), frames"
            f" {int(arrays['lengths'].min())}-{int(arrays['lengths'].max())}"
        ),
        f"{'label':<14}{'N2E':>6}{'E2N':>6}{'train':>7}{'test':>6}",
    ]
    for k, label in enumerate(labels):
        m = arrays["labels"] == k
        n2e, e2n = (int((m & (arrays["kinds"] == kind)).sum()) for kind in (0, 1))
        lines.append(
            f"{label:<14}{n2e:>6}{e2n:>6}"
            f"{int((m & ~held_out).sum()):>7}{int((m & held_out).sum()):>6}"
        )
    per_subject = np.bincount(arrays["subjects"], minlength=spec.num_subjects)
    lines.append(
        f"sequences per subject: min {per_subject.min()}, max {per_subject.max()}"
    )
    for axis, name_ in enumerate("xyz"):
        v = lm[..., axis]
        lines.append(f"{name_} range: {v.min():8.2f} .. {v.max():8.2f} mm")
    w = arrays["au_weights"]
    lines.append(f"AU intensities: {w.min():.2f} .. {w.max():.2f}")
    return "\n".join(lines)


def fingerprints_match(actual, expected, tolerance_mm=1e-3):
    """True if two fingerprints agree: exact metadata, landmark statistics within
    ``tolerance_mm``."""
    if (
        actual["metadata_sha256"] != expected["metadata_sha256"]
        or actual["num_sequences"] != expected["num_sequences"]
    ):
        return False
    keys = [k for k in expected if k.endswith("_mm")]
    return all(abs(actual[k] - expected[k]) <= tolerance_mm for k in keys)


@dataclass
class LandmarkNormalizer:
    """The one invertible map between landmarks in mm and the networks' space.

    x_norm = (x - mean_shape) / scale, with mean_shape (68, 3) the mean landmark frame
    of the training data and scale the std (mm) of what remains.  The DDPM works on
    *absolute* landmarks (paper §3.1): this only recentres and rescales, it removes
      nothing.
    """

    mean_shape: np.ndarray
    scale: float

    @classmethod
    def fit(cls, dataset):
        frames = np.concatenate(
            [dataset.landmarks[i, : dataset.lengths[i]] for i in range(len(dataset))]
        ).astype(np.float64)
        mean = frames.mean(axis=0)
        return cls(mean.astype(np.float32), float((frames - mean).std()))

    def normalize(self, x):
        if isinstance(x, torch.Tensor):
            return (x - torch.as_tensor(self.mean_shape, device=x.device)) / self.scale
        return ((np.asarray(x) - self.mean_shape) / self.scale).astype(np.float32)

    def denormalize(self, x):
        if isinstance(x, torch.Tensor):
            return x * self.scale + torch.as_tensor(self.mean_shape, device=x.device)
        return (np.asarray(x) * self.scale + self.mean_shape).astype(np.float32)

    def to_dict(self):
        return {"mean_shape": np.asarray(self.mean_shape).tolist(), "scale": self.scale}

    @classmethod
    def from_dict(cls, d):
        return cls(np.asarray(d["mean_shape"], dtype=np.float32), float(d["scale"]))


def check_class_names(meta_names, dataset, classifier_type, checkpoint):
    """A classifier must predict exactly the classes of the dataset it is used with."""
    expected = load_dataset(dataset, "train").class_names(classifier_type)
    if tuple(meta_names) != tuple(expected):
        raise ValueError(
            f"checkpoint {checkpoint} predicts {list(meta_names)}, but dataset"
            f" {dataset!r} (type {classifier_type}) has classes {list(expected)}"
        )
    return expected

"""Evaluation metrics (paper §5): accuracy, confusion matrix, FID, diversity, the
realism checks of the denoiser chapter, the filling metrics (error on missing frames,
seam smoothness) and coverage: the label mix, each region's amplitude, precision,
recall, density and coverage of features."""

from __future__ import annotations

import warnings

import numpy as np
import scipy.stats


def accuracy(predicted, true):
    """Fraction of sequences whose predicted class equals the true class."""
    predicted, true = np.asarray(predicted), np.asarray(true)
    if predicted.shape != true.shape:
        raise ValueError(
            f"predicted {predicted.shape} and true {true.shape} must have the same"
            " shape"
        )
    return float((predicted == true).mean())


def confusion_matrix(predicted, true, num_classes):
    """Counts C[i, j] of sequences of true class i predicted as class j."""
    c = np.zeros((num_classes, num_classes), dtype=np.int64)
    np.add.at(c, (np.asarray(true), np.asarray(predicted)), 1)
    return c


def resample_frames(sequences, num_frames):
    """Linearly resample sequences (n, F, ...) to ``num_frames`` frames in normalised
    time."""
    x = np.asarray(sequences, dtype=np.float64)
    src = np.linspace(0.0, 1.0, x.shape[1])
    dst = np.linspace(0.0, 1.0, num_frames)
    idx = np.clip(np.searchsorted(src, dst, side="right") - 1, 0, x.shape[1] - 2)
    w = ((dst - src[idx]) / (src[idx + 1] - src[idx])).reshape(
        (1, -1) + (1,) * (x.ndim - 2)
    )
    return ((1 - w) * x[:, idx] + w * x[:, idx + 1]).astype(np.float32)


def nearest_neighbour_rmse(queries, references, exclude_self=False, return_index=False):
    """For each query sequence, the RMSE (mm) to its closest reference sequence (same
    shape).

    RMSE over all frames, landmarks and coordinates.  Used to check that generated
    sequences are new (not copies of training sequences): compare with held-out real
    sequences. With ``return_index``, also the index of that closest reference.
    """
    import torch

    q = torch.as_tensor(np.asarray(queries, dtype=np.float32)).flatten(1)
    r = torch.as_tensor(np.asarray(references, dtype=np.float32)).flatten(1)
    if q.shape[1] != r.shape[1]:
        raise ValueError(
            f"queries {tuple(q.shape)} and references {tuple(r.shape)} must have the"
            " same sequence shape"
        )
    d = torch.cdist(q.double(), r.double()) / np.sqrt(q.shape[1])
    if exclude_self:
        d.fill_diagonal_(float("inf"))
    best = d.min(dim=1)
    return (
        (best.values.numpy(), best.indices.numpy())
        if return_index
        else best.values.numpy()
    )


def temporal_roughness(sequences):
    """Mean norm (mm) of the second difference over frames: how jerky a landmark motion
    is."""
    x = np.asarray(sequences, dtype=np.float64)
    return float(np.linalg.norm(x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2], axis=-1).mean())


DISTANCE_PAIRS = {  # iBUG-68 landmark pairs: "bone-length-like" distances of a face
    "outer eye corners": (36, 45),
    "inner eye corners": (39, 42),
    "brow span": (17, 26),
    "nose length": (27, 30),
    "nose width": (31, 35),
    "jaw width": (0, 16),
    "face height": (27, 8),
    "mouth width": (48, 54),
    "mouth opening": (51, 57),
    "inner lip gap": (62, 66),
}


def pair_distance(sequences, pair):
    """Distance (mm) between the two landmarks of a DISTANCE_PAIRS entry (e.g. "mouth
    opening": lip midpoints 51 and 57), for every frame: shape
    ``sequences.shape[:-2]``."""
    if pair not in DISTANCE_PAIRS:
        raise ValueError(
            f"unknown landmark pair {pair!r}; known: {sorted(DISTANCE_PAIRS)}"
        )
    i, j = DISTANCE_PAIRS[pair]
    x = np.asarray(sequences, dtype=np.float64)
    return np.linalg.norm(x[..., i, :] - x[..., j, :], axis=-1)


def landmark_statistics(sequences):
    """Per-frame statistics of landmark sequences (n, F, 68, 3): mean inter-landmark
    distances (mm) of DISTANCE_PAIRS, and the mean frame-to-frame speed of a landmark
    (mm per frame).
    """
    x = np.asarray(sequences, dtype=np.float64)
    stats = {
        name: float(np.linalg.norm(x[..., i, :] - x[..., j, :], axis=-1).mean())
        for name, (i, j) in DISTANCE_PAIRS.items()
    }
    stats["frame-to-frame speed"] = float(
        np.linalg.norm(np.diff(x, axis=1), axis=-1).mean()
    )
    return stats


def frechet_distance(features_a, features_b):
    """Fréchet distance between Gaussians fitted to two feature sets (n, d) (the FID of
    Heusel et al. 2017): ||mu_a - mu_b||^2 + tr(C_a + C_b - 2 (C_a C_b)^(1/2)).  The
    paper (§5) feeds it the output of the IC's linear layer, the class logits
    (:meth:`facelib.evaluation.Evaluator.features`)."""
    a, b = (np.asarray(f, dtype=np.float64) for f in (features_a, features_b))
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(
            "features must be two (n, d) arrays with the same d, "
            f"got {a.shape} and {b.shape}"
        )
    if min(len(a), len(b)) < 2:
        raise ValueError(
            "the Fréchet distance needs at least 2 feature vectors per set"
        )
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("features contain NaN or infinite values")
    mu_a, mu_b = a.mean(0), b.mean(0)
    cov_a, cov_b = (
        np.atleast_2d(np.cov(a, rowvar=False)),
        np.atleast_2d(np.cov(b, rowvar=False)),
    )
    # tr((C_a C_b)^(1/2)) = sum of sqrt of the eigenvalues of C_a^(1/2) C_b C_a^(1/2)
    # (symmetric, PSD).
    w, v = np.linalg.eigh(cov_a)
    root_a = (v * np.sqrt(np.clip(w, 0, None))) @ v.T
    cross = np.linalg.eigvalsh(root_a @ cov_b @ root_a)
    trace_sqrt = np.sqrt(np.clip(cross, 0, None)).sum()
    fid = (
        ((mu_a - mu_b) ** 2).sum() + np.trace(cov_a) + np.trace(cov_b) - 2 * trace_sqrt
    )
    # >= 0 exactly; round-off can leave -1e-15 for identical sets
    return float(max(fid, 0.0))


def diversity(features, num_pairs=200, seed=0):
    """Diversity as in Action2Motion / ACTOR / MDM: mean distance between the features
    of ``num_pairs`` random pairs of generated sequences (whatever their labels)."""
    f = np.asarray(features, dtype=np.float64)
    rng = np.random.default_rng(seed)
    i, j = rng.integers(0, len(f), num_pairs), rng.integers(0, len(f), num_pairs)
    keep = i != j
    return float(np.linalg.norm(f[i[keep]] - f[j[keep]], axis=1).mean())


def multimodality(features, labels, num_pairs=20, seed=0):
    """Multimodality as in Action2Motion / ACTOR / MDM: for each label, mean feature
    distance of ``num_pairs`` random pairs of sequences generated for that label;
    averaged over labels."""
    f, y = np.asarray(features, dtype=np.float64), np.asarray(labels)
    rng = np.random.default_rng(seed)
    per_label = []
    for label in np.unique(y):
        members = np.flatnonzero(y == label)
        if len(members) < 2:
            continue
        i, j = rng.choice(members, num_pairs), rng.choice(members, num_pairs)
        keep = i != j
        per_label.append(np.linalg.norm(f[i[keep]] - f[j[keep]], axis=1).mean())
    if not per_label:
        raise ValueError("multimodality needs at least 2 sequences for some label")
    return float(np.mean(per_label))


def missing_frame_error(filled, truth, known):
    """Mean per-landmark Euclidean error (mm) over the unknown frames (known: (n, F) or
    (F,) bool)."""
    a, b = np.asarray(filled, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(
            f"filled {a.shape} and true {b.shape} sequences must have the same shape"
        )
    unknown = ~np.broadcast_to(np.asarray(known, dtype=bool), a.shape[:2])
    return float(np.linalg.norm(a - b, axis=-1)[unknown].mean())


def frame_speeds(sequences):
    """Frame-to-frame motion (mm/frame): the mean over landmarks of ||x_{f+1} - x_f||,
    shape (n, F - 1)."""
    x = np.asarray(sequences, dtype=np.float64)
    return np.linalg.norm(x[:, 1:] - x[:, :-1], axis=-1).mean(-1)


def frame_jerks(sequences):
    """Jerk (mm/frame^3): the mean over landmarks of the third difference
    ||x_{f+3} - 3 x_{f+2} + 3 x_{f+1} - x_f||, shape (n, F - 3); a join that keeps the
    position but not the velocity shows here, not in :func:`frame_speeds`."""
    x = np.asarray(sequences, dtype=np.float64)
    return np.linalg.norm(np.diff(x, n=3, axis=1), axis=-1).mean(-1)


def steps_away_from_seams(known):
    """Mask (n, F - 1) of the frame-to-frame steps between two unknown frames that do
    not touch a seam (no known frame among the step's frames or their neighbours): where
    a filled sequence's own smoothness shows, to compare with :func:`seam_steps`.
    ``known`` (n, F) is True on the given frames.
    """
    k = np.asarray(known, dtype=bool)
    if k.ndim != 2:
        raise ValueError(f"known must be an (n, F) mask, got shape {k.shape}")
    padded = np.pad(k, ((0, 0), (1, 1)), constant_values=False)
    return ~(padded[:, :-3] | padded[:, 1:-2] | padded[:, 2:-1] | padded[:, 3:])


def seam_steps(sequences, known):
    """Seam smoothness: the frame-to-frame motion (mm/frame, as :func:`frame_speeds`)
    across every boundary between a known and an unknown frame.  A seam is invisible
    when this step is no larger than the steps of real sequences (compare with
    ``frame_speeds(real)``); a generated part that does not join the known one shows up
    as one large step.  Returns a flat array, one value per seam.
    """
    x = np.asarray(sequences, dtype=np.float64)
    k = np.broadcast_to(np.asarray(known, dtype=bool), x.shape[:2])
    # a seam between frames f and f + 1 of sequence i
    i, f = np.nonzero(k[:, 1:] != k[:, :-1])
    return frame_speeds(x)[i, f]


def intervals_overlap(a, b):
    """True when the intervals a = (low, high) and b share a point: the data cannot
    order the two estimates (the book reads a difference only where the 95 % intervals
    separate)."""
    return a[0] <= b[1] and b[0] <= a[1]


def interval_order(a, b):
    """How estimate a compares with b, read from their 95 % intervals (low, high):
    "lower" or "higher" where the intervals separate, "overlaps" where the data cannot
    order them.
    """
    if intervals_overlap(a, b):
        return "overlaps"
    return "lower" if a[1] < b[0] else "higher"


def bootstrap_interval(
    statistic, *samples, num_resamples=1000, level=0.95, seed=0, method="BCa"
):
    """Bootstrap interval (low, high) of ``statistic(*samples)`` over their rows:
    how much the number would move with another draw of the same number of rows.

    The samples (arrays with the same first dimension: one row per generated or test
    sequence) are resampled together (paired: the same rows of each), with
    replacement, ``num_resamples`` times, by :func:`scipy.stats.bootstrap` (which
    resamples the row indices; ``seed`` seeds its generator, so the same seed gives
    the same interval).  ``method``:

    * "BCa" (the default): Efron's bias-corrected and accelerated percentile interval.
      It reads the statistic's bias from the share of resamples below it and its
      skew from the n leave-one-out values (n more calls of ``statistic``), and moves
      the percentiles accordingly, which makes the interval of a skewed statistic
      (a mean of skewed data, a variance, a high percentile) closer to ``level``
      coverage than the plain percentile interval.
    * "shifted": the percentile interval of the resamples minus their bias,
      mean(resampled values) - statistic(samples).  For statistics that a resample
      biases by repeating rows, FID, diversity, the k-NN precision and recall: a
      resample acts like fewer distinct sequences and FID grows as n shrinks (the
      evaluation chapter), so its resamples lie mostly above the FID itself; BCa takes
      that for the estimator's bias, and its interval then often misses the FID
      (tests/test_metrics_intervals.py).  The shift keeps the interval on the FID
      with the resamples' spread.

    Degenerate cases fall back to the "shifted" interval of the same resamples: all
    resamples equal (an accuracy of 100 %: then the interval is that single value)
    or a statistic so far in the tail of its resamples that the BCa interval
    excludes it.  A statistic that is NaN or infinite on the samples or on a resample
    raises ValueError.  The interval may pass the statistic's range (an FID below 0);
    callers clip it.
    """
    arrays = [np.asarray(s) for s in samples]
    if not arrays or any(len(a) != len(arrays[0]) for a in arrays):
        raise ValueError(
            f"need samples with the same number of rows, got {[len(a) for a in arrays]}"
        )
    if len(arrays[0]) < 2:
        raise ValueError("a bootstrap interval needs at least 2 rows")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if method not in ("BCa", "shifted"):
        raise ValueError(f"method must be 'BCa' or 'shifted', got {method!r}")

    def of_rows(rows):
        return float(statistic(*(a[rows] for a in arrays)))

    value = float(statistic(*arrays))
    if not np.isfinite(value):
        raise ValueError(f"the statistic is {value} on the samples")
    with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
        # where BCa is undefined scipy warns and returns NaN: handled below
        warnings.simplefilter("ignore", scipy.stats.DegenerateDataWarning)
        result = scipy.stats.bootstrap(
            (np.arange(len(arrays[0])),),
            of_rows,
            n_resamples=num_resamples,
            batch=256,  # bounds the memory of the resampled and leave-one-out indices
            vectorized=False,
            confidence_level=level,
            method="BCa" if method == "BCa" else "percentile",
            rng=np.random.default_rng(seed),
        )
    values = result.bootstrap_distribution
    if not np.isfinite(values).all():
        raise ValueError(
            f"the statistic is NaN or infinite on {(~np.isfinite(values)).sum()} of"
            f" {len(values)} resamples"
        )
    low, high = result.confidence_interval
    if method == "BCa" and np.isfinite([low, high]).all() and low <= value <= high:
        return float(low), float(high)
    low, high = np.quantile(values, [(1 - level) / 2, (1 + level) / 2])
    bias = values.mean() - value
    return float(low - bias), float(high - bias)


def completion_spread(completions, known):
    """How different the completions of one input are: per input, the distance between
    two of its K completions (mm, mean over landmarks and over the unknown frames),
    averaged over the K(K-1)/2 pairs.

    completions: (n, K, F, 68, 3), K >= 2 completions of each of n inputs;
    known: (n, F) bool.  Returns (n,)."""
    c, m = np.asarray(completions), np.asarray(known, bool)
    if c.ndim != 5 or c.shape[1] < 2 or m.shape != (c.shape[0], c.shape[2]):
        raise ValueError(
            "need completions (n, K >= 2, F, 68, 3) and known (n, F), "
            f"got {c.shape} and {m.shape}"
        )
    pairs = [(a, b) for a in range(c.shape[1]) for b in range(a + 1, c.shape[1])]
    dist = np.stack(
        [np.linalg.norm(c[:, a] - c[:, b], axis=-1).mean(-1) for a, b in pairs]
    )  # (pairs, n, F)
    return np.array([dist[:, i, ~m[i]].mean() for i in range(len(m))])


# ----------------------------------------------------------------------------- coverage
# (issue 43) What a generator fails to produce, which means and nearest neighbours do
# not see: the label mix, the amplitude of each region's motion, and how much of the
# data's feature distribution the samples reach.

AMPLITUDE_REGIONS = (
    "mouth opening",
    "mouth-corner excursion",
    "brow raise",
    "eye closure",
)
# middle of each brow to the upper lid below it (iBUG-68)
_BROW_EYE = ((19, 37), (24, 44))
_LIDS = ((37, 41), (38, 40), (43, 47), (44, 46))  # upper to lower eyelid, both eyes
_CORNERS = (48, 54)


def amplitudes(sequences):
    """Each sequence's largest motion of four regions (mm), {region: (n,)}
    (:data:`AMPLITUDE_REGIONS`):

    * mouth opening: the largest inner-lip gap (landmarks 62-66) over the frames;
    * mouth-corner excursion: the diameter of a mouth corner's path (the largest
      distance between two of its positions), the larger of the two corners: how far a
      smile or a pull moves it, wherever the face starts;
    * brow raise: the range over frames of the brow-to-upper-lid distance (landmarks
      19-37, 24-44, averaged);
    * eye closure: the range over frames of the eyelid gap (four lid pairs, averaged).
    Ranges and diameters read a sequence's motion from N2E and E2N alike and ignore
    where the face sits.
    """
    x = np.asarray(sequences, dtype=np.float64)
    if x.ndim != 4 or x.shape[2:] != (68, 3) or x.shape[1] < 2:
        raise ValueError(
            f"expected landmark sequences (n, F >= 2, 68, 3), got {x.shape}"
        )

    def distance(pairs):
        # (n, F)
        return np.mean(
            [np.linalg.norm(x[:, :, i] - x[:, :, j], axis=-1) for i, j in pairs], axis=0
        )

    def diameter(k):
        p = x[:, :, k]  # (n, F, 3)
        return np.linalg.norm(p[:, :, None] - p[:, None], axis=-1).max((1, 2))

    brow, lids = distance(_BROW_EYE), distance(_LIDS)
    return {
        "mouth opening": pair_distance(x, "inner lip gap").max(1),
        "mouth-corner excursion": np.maximum(*(diameter(k) for k in _CORNERS)),
        "brow raise": brow.max(1) - brow.min(1),
        "eye closure": lids.max(1) - lids.min(1),
    }


def label_histogram(labels, num_classes):
    """The share of each class (num_classes,) among integer ``labels``."""
    labels = np.asarray(labels)
    if (
        labels.ndim != 1
        or len(labels) == 0
        or labels.min() < 0
        or labels.max() >= num_classes
    ):
        raise ValueError(
            f"labels must be a non-empty 1-D array of classes in 0..{num_classes - 1}"
        )
    return np.bincount(labels, minlength=num_classes) / len(labels)


def total_variation(p, q):
    """Total variation distance 1/2 sum |p - q| between two histograms (0: the same mix,
    1: disjoint)."""
    p, q = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    if p.shape != q.shape:
        raise ValueError(f"histograms of different lengths: {p.shape} and {q.shape}")
    return float(0.5 * np.abs(p - q).sum())


def subset_total_variations(labels, reference, size, num_subsets=1000, seed=0):
    """The reference for a generated set's label mix: the total variation to
    ``reference`` (a histogram) of ``num_subsets`` random sets of ``size`` real
    ``labels`` drawn with replacement (so that a set as large as the real one still
    varies): how far a real set of that size strays by chance alone.  Returns
    (num_subsets,).
    """
    labels = np.asarray(labels)
    if (
        isinstance(size, bool)
        or not isinstance(size, (int, np.integer))
        or size < 1
        or len(labels) == 0
    ):
        raise ValueError(
            f"need real labels and a positive subset size, got {len(labels)} labels and"
            f" size {size!r}"
        )
    rng = np.random.default_rng(seed)
    k = len(reference)
    return np.array(
        [
            total_variation(
                label_histogram(labels[rng.integers(0, len(labels), size)], k),
                reference,
            )
            for _ in range(num_subsets)
        ]
    )


def _people_groups(people):
    """The row indices of each person of ``people`` (m,) ids, in id order."""
    ids, inverse = np.unique(np.asarray(people), return_inverse=True)
    if len(ids) < 2:
        raise ValueError(f"need the sequences of 2 or more people, got {len(ids)}")
    return [np.flatnonzero(inverse == k) for k in range(len(ids))]


def population_gap(
    generated, reference, people, statistic, num_resamples=2000, level=0.95, seed=0
):
    """How far ``statistic`` (a function of a 1-D array, e.g. the 90th percentile) of
    ``generated`` values sits from that of a reference population, with its bootstrap
    interval: (difference, (low, high)) of statistic(generated) - statistic(reference).

    The generated values (one per sample; the samples of several seeds pooled, each an
    independent draw, so that the interval holds the seed-to-seed spread) are resampled
    by row; the reference values (m,) by person (``people`` (m,) ids: a person's
    sequences are resampled together, since they share a face and a style), the two
    independently (:func:`scipy.stats.bootstrap`, unpaired, percentile interval;
    ``seed`` seeds it).  A generator that reproduces the population scores an interval
    containing 0 (the evaluation chapter's coverage protocol)."""
    generated = np.asarray(generated, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if generated.ndim != 1 or len(generated) < 2 or reference.shape != np.shape(people):
        raise ValueError(
            "need 2 or more generated values (n,) and reference values (m,) with a"
            f" person id each, got shapes {generated.shape}, {reference.shape} and"
            f" {np.shape(people)}"
        )
    groups = [reference[g] for g in _people_groups(people)]

    def difference(g, chosen):
        chosen = [groups[int(k)] for k in chosen]
        return statistic(g) - statistic(np.concatenate(chosen))

    result = scipy.stats.bootstrap(
        (generated, np.arange(len(groups))),
        difference,
        paired=False,
        vectorized=False,
        n_resamples=num_resamples,
        confidence_level=level,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    ci = result.confidence_interval
    value = difference(generated, range(len(groups)))
    return float(value), (float(ci.low), float(ci.high))


def label_mix_gap(
    generated, reference, people, num_classes, num_resamples=1000, level=0.95, seed=0
):
    """A generated set's label mix against a reference population's, as read by one
    classifier: ``generated`` (n,) and ``reference`` (m,) its predicted classes,
    ``people`` (m,) the reference's person ids.  Returns a dict:

    * "mix", "reference_mix": the two histograms;
    * "tv": their total variation; "max_ratio": the largest share of a class over its
      reference share (a label made too often: 1.5 is half as often again);
    * "tv_real", "max_ratio_real": the ``level`` percentile of the same two
      statistics over ``num_resamples`` real sets of the generated set's size (people
      drawn with replacement, then n of their sequences): how far a real set of that
      size strays by chance.  A generator whose numbers lie below them makes the
      labels as real people do."""
    generated, reference = np.asarray(generated), np.asarray(reference)
    groups = _people_groups(people)
    target = label_histogram(reference, num_classes)
    if (target == 0).any():
        raise ValueError("every class must occur in the reference population")

    def statistics(labels):
        mix = label_histogram(labels, num_classes)
        return mix, total_variation(mix, target), float((mix / target).max())

    mix, tv, ratio = statistics(generated)
    rng = np.random.default_rng(seed)
    real = []
    for _ in range(num_resamples):
        drawn = rng.integers(0, len(groups), len(groups))
        pool = np.concatenate([groups[k] for k in drawn])
        real.append(statistics(reference[rng.choice(pool, len(generated))])[1:])
    real = np.array(real)
    return {
        "mix": mix,
        "reference_mix": target,
        "tv": tv,
        "max_ratio": ratio,
        "tv_real": float(np.percentile(real[:, 0], 100 * level)),
        "max_ratio_real": float(np.percentile(real[:, 1], 100 * level)),
    }


def _kth_neighbour_radii(features, k):
    """Distance of each row of ``features`` to its k-th nearest other row."""
    d = np.linalg.norm(features[:, None] - features[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    return np.sort(d, axis=1)[:, k - 1]


def precision_recall_coverage(real, generated, k=5):
    """Fidelity and coverage of generated features against real ones (rows: sequences):

    * precision (Kynkäänniemi et al. 2019): the share of generated rows inside some
      real row's k-NN ball;
    * recall: the share of real rows inside some generated row's k-NN ball (the data
      the generator reaches);
    * density (Naeem et al. 2020): the mean number of real balls a generated row
      falls in, divided by k;
    * coverage (Naeem et al. 2020): the share of real rows whose own k-NN ball holds
      a generated row, which, unlike recall, a few outlying samples cannot inflate.
    Returns a dict of the four (Python floats)."""
    real = np.asarray(real, dtype=np.float64)
    generated = np.asarray(generated, dtype=np.float64)
    if real.ndim != 2 or generated.ndim != 2 or real.shape[1] != generated.shape[1]:
        raise ValueError(
            f"need feature matrices (n, D) of one width, got {real.shape} "
            f"and {generated.shape}"
        )
    largest = min(len(real), len(generated)) - 1
    if (
        isinstance(k, bool)
        or not isinstance(k, (int, np.integer))
        or not 1 <= k <= largest
    ):
        raise ValueError(f"k must be an integer in 1..{largest}, got {k!r}")
    real_radii = _kth_neighbour_radii(real, k)
    generated_radii = _kth_neighbour_radii(generated, k)
    d = np.linalg.norm(generated[:, None] - real[None], axis=-1)  # (generated, real)
    inside_real = d <= real_radii[None]
    return {
        "precision": float(inside_real.any(1).mean()),
        "recall": float((d <= generated_radii[:, None]).any(0).mean()),
        "density": float(inside_real.sum(1).mean() / k),
        "coverage": float((d.min(0) <= real_radii).mean()),
    }

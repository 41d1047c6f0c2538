"""The paper's evaluation protocol (§5): an independent classifier (IC) scores generated
sequences.

* IC: one LSTM layer + a linear layer (models/classifier.py), trained on the training
  split and never used for guidance; of type "I" (label) or "S" (label x N2E/E2N).
* Accuracy: how often the IC recognises the requested class in the generated sequences.
* FID: Fréchet distance between IC features of generated and of training sequences.  The
  paper computes it "from the output of the linear layer of the IC": the class logits,
  which we use too (12 numbers for 12 labels; a feature space where only what the IC
  learned to tell apart counts).
* Diversity and multimodality (Action2Motion, ACTOR, MDM) on the same features.
* The "ground truth" row: the held-out test sequences scored exactly like generated
  ones, i.e. what an ideal generator that reproduced the test set would get.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import ks_2samp

from . import config, data, metrics
from .checkpoints import checkpoint_name, load_checkpoint
from .face.aus import AU_NAMES
from .models.classifier import ARCHITECTURES, SequenceClassifier, classifier_from_config


@dataclass
class Evaluator:
    """An IC with the training-set features that FID compares against."""

    model: SequenceClassifier
    dataset: str
    classifier_type: str
    class_names: tuple
    reference_features: np.ndarray  # IC features (logits) of the training sequences

    @torch.no_grad()
    def features(self, sequences, batch_size=256):
        """Output of the IC's linear layer (n, num_classes) for sequences (n, F, 68, 3)
        in mm."""
        x = torch.as_tensor(check_sequences(sequences), dtype=torch.float32)
        return torch.cat(
            [self.model(x[i : i + batch_size]) for i in range(0, len(x), batch_size)]
        ).numpy()

    def score(self, sequences, targets, seed=0, intervals=False, num_resamples=1000):
        """Accuracy (%), FID, diversity and multimodality (Python floats) of sequences
        generated for ``targets``.

        With ``intervals``, also ``accuracy_ci``, ``fid_ci`` and ``diversity_ci``: 95 %
        bootstrap intervals over the sequences (:func:`metrics.bootstrap_interval`
        from ``num_resamples`` resamples; each FID resample costs a matrix square root,
        so chapters pass 200): BCa for the accuracy; for FID and diversity, which a
        resample biases by repeating sequences, the percentile interval shifted by the
        resamples' bias (``method="shifted"``).  The bias correction may move an
        interval past the statistic's range: accuracy is clipped to [0, 100] and FID
        to [0, inf).
        """
        targets = np.asarray(targets)
        if targets.shape != (len(sequences),):
            raise ValueError(
                f"need one target per sequence: {len(sequences)} sequences, targets"
                f" {targets.shape}"
            )
        f = self.features(sequences)
        scores = {
            "accuracy": float(self._accuracy(f, targets)),
            "fid": float(self._fid(f)),
            "diversity": float(metrics.diversity(f, seed=seed)),
            "multimodality": float(metrics.multimodality(f, targets, seed=seed)),
        }
        if intervals:

            def interval(statistic, *samples, method="BCa"):
                low, high = metrics.bootstrap_interval(
                    statistic,
                    *samples,
                    num_resamples=num_resamples,
                    seed=seed,
                    method=method,
                )
                return float(low), float(high)

            low, high = interval(self._accuracy, f, targets)
            scores["accuracy_ci"] = (max(low, 0.0), min(high, 100.0))
            low, high = interval(self._fid, f, method="shifted")
            scores["fid_ci"] = (max(low, 0.0), high)
            scores["diversity_ci"] = interval(
                lambda g: metrics.diversity(g, seed=seed), f, method="shifted"
            )
        return scores

    def accuracy_per_class(self, sequences, targets):
        """{class name: accuracy (%) on the sequences requested as that class}, for the
        classes present in ``targets``: whether guidance helps for every label, not only
        on average."""
        targets = np.asarray(targets)
        hits = self.features(sequences).argmax(1) == targets
        return {
            self.class_names[c]: float(100 * hits[targets == c].mean())
            for c in np.unique(targets)
        }

    @staticmethod
    def _accuracy(features, targets):
        return 100 * metrics.accuracy(features.argmax(1), targets)

    def _fid(self, features):
        return metrics.frechet_distance(features, self.reference_features)

    def ground_truth(self, seed=0, intervals=False):
        """The GT row: the held-out test sequences scored like generated ones."""
        test = data.load_dataset(self.dataset, "test")
        return self.score(
            test.landmarks,
            test.targets(self.classifier_type),
            seed=seed,
            intervals=intervals,
        )

    def coverage(self, sequences, k=5, num_subsets=1000, num_resamples=200, seed=0):
        """What ``sequences`` (n, F, 68, 3) in mm cover of the training split, and the
        test split as the reference row (an ideal generator would score like it); the
        coverage protocol of the evaluation chapter:

        * "label_tv": the total variation between the IC's label mix of the sequences
          and of the training split, with "label_tv_real_p95": the 95th percentile of
          the same statistic over random real test subsets of the same size drawn from
          the test split (:func:`metrics.subset_total_variations`), and "label_mix" the
          sequences' own mix;
        * "amplitudes": per region (:func:`metrics.amplitudes`) the 50th and 90th
          percentiles (mm) and the two-sample Kolmogorov-Smirnov p-value against the
          test split;
        * precision, recall, density, coverage of the IC features against the training
          split's (k-NN balls, :func:`metrics.precision_recall_coverage`), each with a
          95 % bootstrap interval over the sequences (resampling repeats rows, which
          shrinks their balls: the intervals are rough; "shifted" ones, as for FID,
          and no BCa, whose n leave-one-out values would cost n more k-NN
          searches).
        Returns {"generated": ..., "test": ...}, the same keys for each."""
        test = data.load_dataset(self.dataset, "test")
        train_mix = metrics.label_histogram(
            self.reference_features.argmax(1), len(self.class_names)
        )
        test_amplitudes = metrics.amplitudes(test.landmarks)
        test_predicted = self.features(test.landmarks).argmax(1)

        def measure(x):
            f = self.features(x)
            mix = metrics.label_histogram(f.argmax(1), len(self.class_names))
            amp = metrics.amplitudes(x)
            row = {
                "n": len(x),
                "label_mix": dict(zip(self.class_names, mix.round(4).tolist())),
                "label_tv": metrics.total_variation(mix, train_mix),
                "label_tv_real_p95": float(
                    np.percentile(
                        metrics.subset_total_variations(
                            test_predicted, train_mix, len(x), num_subsets, seed
                        ),
                        95,
                    )
                ),
                "amplitudes": {
                    region: {
                        "p50": float(np.percentile(a, 50)),
                        "p90": float(np.percentile(a, 90)),
                        "ks_p_vs_test": float(
                            ks_2samp(a, test_amplitudes[region]).pvalue
                        ),
                    }
                    for region, a in amp.items()
                },
            }
            for name in ("precision", "recall", "density", "coverage"):

                def statistic(g, name=name):
                    return metrics.precision_recall_coverage(
                        self.reference_features, g, k
                    )[name]

                row[name] = statistic(f)
                low, high = metrics.bootstrap_interval(
                    statistic,
                    f,
                    num_resamples=num_resamples,
                    seed=seed,
                    method="shifted",
                )
                row[name + "_ci"] = (
                    max(low, 0.0),
                    high if name == "density" else min(high, 1.0),
                )
            return row

        return {
            "generated": measure(check_sequences(sequences)),
            "test": measure(test.landmarks),
        }

    def class_index(self, name):
        """Index of a class name; a clear error listing the valid names otherwise."""
        if name not in self.class_names:
            raise ValueError(
                f"unknown class {name!r} for dataset {self.dataset!r} (type"
                f" {self.classifier_type}); allowed: {', '.join(self.class_names)}"
            )
        return self.class_names.index(name)


def check_sequences(sequences):
    """Validate landmark sequences (n, F, 68, 3), finite; returns a float32 array."""
    x = np.ascontiguousarray(sequences, dtype=np.float32)
    if x.ndim != 4 or x.shape[2:] != (68, 3) or len(x) == 0:
        raise ValueError(
            f"expected landmark sequences of shape (n, frames, 68, 3), got {x.shape}"
        )
    if not np.isfinite(x).all():
        raise ValueError("landmark sequences contain NaN or infinite values")
    return x


def load_evaluator(dataset="coma", classifier_type="I", name=None, reader="lstm"):
    """Load the shipped IC ic_<dataset>_<type> (sha256 checked) and the training
    features for FID; ``reader`` "cnn": the second reader ic_<dataset>_<type>_cnn (a
    temporal CNN, models.classifier), scored the same way."""
    data.check_dataset_name(dataset)
    data.check_classifier_type(classifier_type)
    if reader not in ARCHITECTURES:
        raise ValueError(
            f"unknown reader {reader!r}; allowed: {', '.join(ARCHITECTURES)}"
        )
    name = name or checkpoint_name("ic", dataset, classifier_type) + (
        "" if reader == "lstm" else f"_{reader}"
    )
    model, meta = load_checkpoint(name, "evaluator", classifier_from_config)
    names = data.check_class_names(meta["class_names"], dataset, classifier_type, name)
    evaluator = Evaluator(
        model, dataset, classifier_type, names, np.zeros((0, len(names)))
    )
    evaluator.reference_features = evaluator.features(
        data.load_dataset(dataset, "train").landmarks
    )
    return evaluator


# the two percentiles of each region's amplitudes that the population protocol compares
POPULATION_PERCENTILES = (50, 90)


def population_gap(
    sequences, dataset="coma", readers=ARCHITECTURES, num_resamples=2000, seed=0
):
    """The coverage protocol against a reference population of new people (issue 58,
    the evaluation chapter): how far ``sequences`` (n, F, 68, 3) in mm, generated
    without a label (the samples of several seeds pooled), sit from what the dataset's
    reference population does (config.REFERENCE_POPULATIONS: 50 new people performing
    its labels).  Returns a dict:

    * "amplitudes": {region: {"p50": (gap, (low, high)), "p90": ...}}: each
      percentile of each sequence's largest motion (metrics.amplitudes) generated
      minus reference, in mm, with its 95 % interval (metrics.population_gap:
      generated resampled by sample, the reference by person);
    * "label_mix": {reader: metrics.label_mix_gap of the reader's predicted labels},
      for the IC ("lstm") and the second reader ("cnn"), with the class names.
    """
    reference = data.load_dataset(config.REFERENCE_POPULATIONS[dataset], "test")
    x = check_sequences(sequences)
    generated_amplitudes = metrics.amplitudes(x)
    reference_amplitudes = metrics.amplitudes(reference.landmarks)
    out = {"n": len(x), "amplitudes": {}, "label_mix": {}}
    for region, values in generated_amplitudes.items():
        out["amplitudes"][region] = {
            f"p{q}": metrics.population_gap(
                values,
                reference_amplitudes[region],
                reference.subjects,
                lambda v, q=q: np.percentile(v, q),
                num_resamples=num_resamples,
                seed=seed,
            )
            for q in POPULATION_PERCENTILES
        }
    for reader in readers:
        ev = load_evaluator(dataset, "I", reader=reader)
        gap = metrics.label_mix_gap(
            ev.features(x).argmax(1),
            ev.features(reference.landmarks).argmax(1),
            reference.subjects,
            len(ev.class_names),
            seed=seed,
        )
        out["label_mix"][reader] = gap | {"class_names": list(ev.class_names)}
    return out


# the noise levels at which the held-out denoising loss is read (of T = 2000)
LOSS_TIMES = (50, 200, 600, 1200)


@torch.no_grad()
def denoising_loss(denoiser, landmarks, times=LOSS_TIMES, draws=4, seed=0):
    """The simple loss of Eq. 8, ||eps - eps_theta(x_t, t)||^2 averaged over
    ``landmarks`` (n, F, 68, 3) in mm and ``draws`` noise draws per sequence, at each
    step t of ``times``: {t: loss}.  The same noise for every model and dataset given
    the same ``seed`` and n, so that models and splits compare draw for draw; the
    noise estimate whatever the network predicts (the models compare on one scale).
    Read on the training split, on new takes of the training people (coma_retakes)
    and on new people, it separates replaying the training sequences from meeting new
    anatomy (issue 58)."""
    x0 = denoiser.to_model(landmarks)
    generator = torch.Generator().manual_seed(seed)
    out = {}
    for t in times:
        total = 0.0
        for _ in range(draws):
            eps = torch.randn(x0.shape, generator=generator, dtype=x0.dtype)
            step = torch.full((len(x0),), t)
            xt = denoiser.diffusion.q_sample(x0, step, eps.to(x0.device))
            labels = denoiser.diffusion.time_labels[step].to(x0.device)
            pred = torch.cat(
                [
                    denoiser.model(xt[i : i + 256], labels[i : i + 256])
                    for i in range(0, len(x0), 256)
                ]
            )
            total += float(((eps.to(x0.device) - pred) ** 2).mean())
        out[t] = total / draws
    return out


def compare(generators, evaluator, targets, num_resamples=1000):
    """The rows of a table of methods: run each of ``generators`` ({name: callable() ->
    sequences (n, F, 68,
    3) in mm}) and score its sequences with ``evaluator`` against ``targets`` (n,).
       Returns {name: the
    scores of :meth:`Evaluator.score` with their 95 % intervals, plus "seconds", the
    generator's wall time} and {name: its sequences}."""
    rows, outputs = {}, {}
    for name, generate in generators.items():
        t0 = time.perf_counter()
        outputs[name] = generate()
        seconds = time.perf_counter() - t0
        rows[name] = evaluator.score(
            outputs[name], targets, intervals=True, num_resamples=num_resamples
        )
        rows[name]["seconds"] = seconds
    return rows, outputs


@torch.no_grad()
def accuracy_by_noise(
    classifier, denoiser, dataset, t_grid, classifier_type="I", seed=0
):
    """Accuracy (%) of a classifier of noisy sequences (the guide of Alg. 1 or 4) on
    ``dataset``'s sequences noised to each step of ``t_grid`` with Eq. 3, one fresh draw
    of noise per sequence and step; the classifier reads the denoiser's normalised space
    and the time label t."""
    x0 = torch.as_tensor(denoiser.normalizer.normalize(dataset.landmarks))
    y = torch.as_tensor(dataset.targets(classifier_type))
    generator, accuracies = torch.Generator().manual_seed(seed), []
    for t in t_grid:
        xt = denoiser.diffusion.q_sample(
            x0, torch.full((len(x0),), t), generator=generator
        )
        predicted = classifier(xt, torch.full((len(x0),), float(t))).argmax(1)
        accuracies.append(100 * (predicted == y).float().mean().item())
    return accuracies


@torch.no_grad()
def au_error_by_noise(
    regressor, denoiser, dataset, t_grid, seed=0, active=None, aus=None
):
    """Mean absolute error (intensity units) of a noisy AU regressor R(x_t, t) (AU-curve
    control) on ``dataset``'s sequences noised to each step of ``t_grid`` with Eq. 3,
    against the AU curves that made them, over every frame and AU; one fresh draw of
    noise per sequence and step.  ``aus``: only these AUs (a non-empty list of names of
    ``face.aus.AU_NAMES``; None: all); ``active``: only the entries where the true
    |intensity| exceeds it (a number >= 0: the frames where an AU acts; most entries are
    0, which predicting no AU at all gets right).  A ValueError when no entry is
    counted."""
    if aus is not None:
        if isinstance(aus, str) or not isinstance(aus, (list, tuple)) or not aus:
            raise ValueError(
                "aus must be a non-empty list of AU names (e.g. ['AU26']) or None for"
                f" all, got {aus!r}"
            )
        unknown = sorted(set(aus) - set(AU_NAMES))
        if unknown:
            raise ValueError(
                f"aus: unknown AUs {unknown}; allowed: {', '.join(AU_NAMES)}"
            )
    if active is not None and (
        isinstance(active, bool)
        or not isinstance(active, (int, float))
        or not 0 <= active < np.inf
    ):
        raise ValueError(
            f"active must be None (every entry) or an intensity >= 0, got {active!r}"
        )
    x0 = torch.as_tensor(denoiser.normalizer.normalize(dataset.landmarks))
    truth = torch.as_tensor(dataset.au_weights, dtype=torch.float32)
    chosen = torch.zeros(len(AU_NAMES), dtype=torch.bool)
    chosen[[AU_NAMES.index(a) for a in (AU_NAMES if aus is None else aus)]] = True
    counted = chosen & (
        truth.abs() > active
        if active is not None
        else torch.ones_like(truth, dtype=torch.bool)
    )
    if not counted.any():
        raise ValueError(
            f"no entry to count: none of aus={aus!r} exceeds active={active!r} in these"
            " sequences"
        )
    generator, errors = torch.Generator().manual_seed(seed), []
    for t in t_grid:
        xt = denoiser.diffusion.q_sample(
            x0, torch.full((len(x0),), t), generator=generator
        )
        errors.append(
            (regressor(xt, torch.full((len(x0),), float(t))) - truth)
            .abs()[counted]
            .mean()
            .item()
        )
    return errors

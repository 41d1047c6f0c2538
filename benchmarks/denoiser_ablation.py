"""What makes the denoiser under-produce wide and rare expressions?  Ablations of its
training (issue 43).

Usage: python benchmarks/denoiser_ablation.py [--dataset coma] [--steps 3000] [--only
NAME ...] [--train-only]
                                              [--sample-steps 500] [--n N] [--save NAME]

Each row trains the shipped denoiser's recipe (facelib/training/settings.py, DenoiserTraining) with
one change, at a reduced budget (``--steps``), into the cache
(``<cache>/denoiser_ablation/NAME``; a finished run is reused, a stopped one resumed),
then measures its unconditional samples (``--n``, default the test split's size, at the
command line's default ``--sample-steps``) with the coverage protocol of the evaluation
chapter (Evaluator.coverage: label mix, amplitudes per region,
precision/recall/density/coverage in the IC's feature space) and FID against the
training split, with 95 % intervals, and the training's wall time.  The held-out losses
per noise-level bucket (recipes.DenoiserRecipe.validate, every 500 steps) go to a second
table, NAME_curves.

Training runs can be spread over processes (each with OMP_NUM_THREADS=1) with --only and
--train-only; the final run, without them, trains nothing that is done and measures
  every row:

    OMP_NUM_THREADS=1 python benchmarks/denoiser_ablation.py --train-only --only
    baseline x0 ... &
    python benchmarks/denoiser_ablation.py --save denoiser_ablation        # about 3 h of training in all on 2 cores
"""

import argparse
import dataclasses
import json
import shutil
import time

import numpy as np

from facelib import config, data, evaluation, metrics, results, tasks, training
from facelib.checkpoints import checkpoint_paths
from facelib.models.denoiser import DenoiserConfig

# name -> (what it changes, DenoiserTraining settings, DenoiserConfig changes)
VARIANTS = {
    "baseline": (
        "none: the recipe (eps, linear, uniform weighting, 128 x 4, EMA 0.999)",
        {},
        {},
    ),
    "x0": ("predict x_0 (MDM)", {"prediction": "x0"}, {}),
    "v": ("predict v (Salimans & Ho 2022)", {"prediction": "v"}, {}),
    "min_snr": ("min-SNR-5 weighting (Hang et al. 2023)", {"min_snr_gamma": 5.0}, {}),
    "cosine": ("cosine schedule (Nichol & Dhariwal 2021)", {"schedule": "cosine"}, {}),
    "no_ema": ("no EMA of the weights", {"ema_decay": None}, {}),
    "mirror": ("left-right mirroring, p = 0.5", {"mirror": 0.5}, {}),
    "wide": ("width 192, feed-forward 384", {}, {"width": 192, "ff": 384}),
    "deep": ("depth 6", {}, {"depth": 6}),
    "x4": ("4x the steps", {"steps_factor": 4}, {}),
    "x8": ("8x the steps", {"steps_factor": 8}, {}),
}
REGIONS = metrics.AMPLITUDE_REGIONS
COLUMNS = (
    ["row", "change", "training steps", "label TV", "real subsets' TV p95"]
    + [f"{r} p90 (mm)" for r in REGIONS]
    + [f"{r} KS p vs test" for r in REGIONS]
    + [
        c
        for name in ("precision", "recall", "density", "coverage")
        for c in (name, "95 % interval")
    ]
    + ["FID", "FID 95 % interval", "training seconds", "sampling seconds"]
)


def run_dir():
    return config.cache_dir() / "denoiser_ablation"


def recipe_for(name, dataset, steps):
    """The recipe of row ``name``: the shipped denoiser's with the row's change, for
    ``steps`` steps."""
    _, settings, architecture = VARIANTS[name]
    settings = dict(settings)
    steps *= settings.pop("steps_factor", 1)
    chosen = training.settings_for("denoiser", dataset=dataset, steps=steps, **settings)
    model_config = None
    if architecture:
        model_config = DenoiserConfig(
            num_diffusion_steps=chosen.num_diffusion_steps,
            schedule=chosen.schedule,
            prediction=chosen.prediction,
            **architecture,
        )
    return training.DenoiserRecipe(chosen, model_config)


def trained(name, dataset, steps):
    """Train row ``name`` into the cache unless it is there (a stopped run resumes);
    returns its stem.

    A row whose recipe is the shipped checkpoint's (its recorded settings and
    architecture) is that checkpoint, which training reproduces bit for bit
    (tests/test_training.py): it is copied, not retrained (it has no held-out curve: it
    was trained before they were logged)."""
    stem = run_dir() / f"{dataset}_{steps}_{name}"
    if not checkpoint_paths(stem)[1].exists():  # train_and_save writes the .json last
        recipe = recipe_for(name, dataset, steps)
        shipped = f"denoiser_{dataset}"
        if not VARIANTS[name][2] and training.trained_on_this_world(
            shipped, "denoiser", dict(dataclasses.asdict(recipe.settings))
        ):
            for source, target in zip(
                checkpoint_paths(shipped), checkpoint_paths(stem)
            ):
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(source, target)
            print(f"{name}: the shipped {shipped} has this recipe; copied", flush=True)
            return stem
        print(f"training {name}: {recipe.settings.steps} steps", flush=True)
        training.train_and_save(recipe, name=str(stem), progress=False, resume=True)
    return stem


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="coma", choices=["coma", "bu"])
    parser.add_argument(
        "--steps",
        type=int,
        default=3000,
        help="training steps of a row (a quarter of the full)",
    )
    parser.add_argument(
        "--only", nargs="+", choices=list(VARIANTS), help="these rows only"
    )
    parser.add_argument(
        "--train-only", action="store_true", help="train the rows, measure nothing"
    )
    parser.add_argument(
        "--sample-steps",
        type=int,
        default=tasks.Unconditional().steps,
        help="respaced reverse steps of the samples (default: the command line's)",
    )
    parser.add_argument(
        "--n",
        type=int,
        default=None,
        help="samples per row (default: the test split's size)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)
    if args.save and (args.only or args.train_only):
        parser.error(
            "--only and --train-only measure part of the table: they cannot --save it"
        )
    names = args.only or list(VARIANTS)
    t_start = time.perf_counter()
    stems = {name: trained(name, args.dataset, args.steps) for name in names}
    if args.train_only:
        return
    ev = evaluation.load_evaluator(args.dataset, "I")
    test = data.load_dataset(args.dataset, "test")
    n = args.n or len(test)
    rows, curves = [], []
    for name in names:
        denoiser = tasks.load_denoiser(str(stems[name]))
        meta = denoiser.meta
        t0 = time.perf_counter()
        x = tasks.unconditional(
            n, steps=args.sample_steps, seed=0, denoiser=denoiser, progress=False
        )
        sampling = time.perf_counter() - t0
        measured = ev.coverage(x)
        if not rows:
            t = measured["test"]
            scores = ev.score(
                test.landmarks, test.targets("I"), intervals=True, num_resamples=200
            )
            rows.append(
                _row(
                    "test split",
                    "held-out real sequences (the reference)",
                    "",
                    t,
                    scores,
                    0.0,
                    0.0,
                )
            )
        scores = ev.score(x, np.zeros(len(x), int), intervals=True, num_resamples=200)
        rows.append(
            _row(
                name,
                VARIANTS[name][0],
                meta["training"]["steps"],
                measured["generated"],
                scores,
                meta.get("wall_time_s"),
                sampling,
            )
        )
        print(json.dumps(rows[-1]), flush=True)
        if (
            "held_out" not in meta["history"]
        ):  # a copy of a checkpoint trained before the curves were logged
            continue
        held_out = meta["history"]["held_out"]
        buckets = [k for k in held_out if k != "step"]
        curves += [
            [name, step, *[held_out[b][i] for b in buckets]]
            for i, step in enumerate(held_out["step"])
        ]
    if args.save:
        run = results.Run(
            allow_dirty=args.allow_dirty,
            settings=(training.DenoiserTraining(), tasks.Unconditional()),
            checkpoints=[f"ic_{args.dataset}_I"],
            seeds=[0],
            n=n,
            steps=[args.sample_steps],
            wall_time_s=time.perf_counter() - t_start,
        )
        path = results.save_result(
            args.save,
            f"Denoiser ablations ({args.dataset}): coverage of unconditional samples, "
            f"{args.steps} training steps a row (x4, x8: 4 and 8 times)",
            COLUMNS,
            rows,
            run,
            notes=(
                f"each row: the shipped recipe with one change, {args.steps} steps (x4,"
                f" x8: 4 and 8 times as many), batch 64, seed 0; {n} samples at"
                f" {args.sample_steps} respaced steps, seed 0; coverage as in"
                " coverage_unconditional (against the training split, type-I IC"
                " features, k = 5); training seconds as each run recorded them (runs"
                " side by side with one thread each, x8 alone with two; x4 is the"
                " checkpoint shipped before issue 43, timed beside other runs)"
            ),
        )
        print(f"saved {path}")
        path = results.save_result(
            args.save + "_curves",
            "Held-out loss per noise level during the ablations' training"
            f" ({args.dataset})",
            ["row", "step"] + [f"held-out eps loss, {b}" for b in buckets],
            curves,
            run,
            notes=(
                "Eq. 8's loss on up to 256 test sequences, the same draws at every"
                " evaluation, of the model the run would return (its EMA); buckets of"
                " paper steps t"
            ),
        )
        print(f"saved {path}")


def _row(name, change, steps, measured, scores, training_seconds, sampling_seconds):
    amp = measured["amplitudes"]
    return (
        [name, change, steps, measured["label_tv"], measured["label_tv_real_p95"]]
        + [amp[r]["p90"] for r in REGIONS]
        + [amp[r]["ks_p_vs_test"] for r in REGIONS]
        + [
            v
            for key in ("precision", "recall", "density", "coverage")
            for v in (measured[key], list(measured[key + "_ci"]))
        ]
        + [scores["fid"], list(scores["fid_ci"]), training_seconds, sampling_seconds]
    )


if __name__ == "__main__":
    main()

"""What makes the denoiser under-produce wide and rare expressions?  Ablations of its
training (issues 43 and 58).

Usage: python benchmarks/denoiser_ablation.py [--dataset coma] [--steps 6000] [--only
NAME ...] [--train-only] [--sample-steps 500] [--n 64] [--seeds 0 1 2 3 4] [--renoise N
[--renoise-rows NAME ...]] [--save NAME]

Each row trains the denoiser's recipe as it was before issue 58 (DenoiserTraining with
a Gaussian part per frame: BEFORE) with one change, at a reduced budget (``--steps``, a
quarter of the recipe's), into the cache (``<cache>/denoiser_ablation/<dataset>_<steps>_NAME``; a
finished run is reused, a stopped one resumed), then measures it with the population
protocol of the evaluation chapter (evaluation.population_gap): ``--n`` unconditional
samples for each of ``--seeds`` pooled, at the command line's default
``--sample-steps``; per region the median and 90th percentile of each sequence's largest
motion minus the reference population's (50 new people), with 95 % intervals by person;
the label mix by both readers beside real sets' 95th percentile; the denoising loss at
t = 200 on the training split, on new takes of its people and on new people
(evaluation.denoising_loss); and the training's wall time.  The held-out losses per
noise-level bucket (recipes.DenoiserRecipe.validate, every 500 steps) go to a second
table, NAME_curves; with ``--renoise N``, where along the chain each of
``--renoise-rows`` loses the amplitude (:func:`renoised`) to a third, NAME_renoise.

Training runs can be spread over processes (each with OMP_NUM_THREADS=1) with --only and
--train-only; a run with --save measures the rows named (all without --only) and trains
nothing that is done:

    OMP_NUM_THREADS=1 python benchmarks/denoiser_ablation.py --train-only --only baseline crowd world_faces &
    OMP_NUM_THREADS=1 python benchmarks/denoiser_ablation.py --train-only --only motion_weight dropout &
    python benchmarks/denoiser_ablation.py --save denoiser_ablation   # about 2.5 h on 2 cores

A row whose recipe is a shipped checkpoint's is that checkpoint (copied, not retrained:
temporal_prior_x4 is denoiser_coma's recipe, x4 the one shipped before it); x8
(48,000 steps), the
other targets, schedules and sizes of issue 43 and weight decay run with --only.
"""

import argparse
import dataclasses
import json
import shutil
import time
from pathlib import Path

import numpy as np
import torch

from facelib import config, data, evaluation, metrics, results, tasks, training
from facelib.checkpoints import checkpoint_paths
from facelib.models.denoiser import DenoiserConfig

# every row but the temporal prior's changes the recipe as it was before issue 58, whose
# Gaussian part treats frames independently
BEFORE = {"temporal_prior": False}
# name -> (what it changes, DenoiserTraining settings, DenoiserConfig changes)
VARIANTS = {
    "baseline": (
        "none: the recipe before issue 58 (eps, linear, uniform weighting, 128 x 4, EMA"
        " 0.999, a Gaussian part per frame)",
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
    "x4": ("4x the steps (the recipe shipped before issue 58)", {"steps_factor": 4}, {}),
    "x8": ("8x the steps", {"steps_factor": 8}, {}),
    # issue 58: data and regularisation, representation
    "crowd": (
        "5x the people: CoMA's 9 and 36 more (coma+crowd, 2248 sequences)",
        {"dataset": "coma+crowd"},
        {},
    ),
    "world_faces": (
        "anatomy pool + 500 new faces of the world (recipes.WORLD_ANATOMIES)",
        {"anatomy_pool": ("coma", "bu", "world")},
        {},
    ),
    "motion_weight": (
        "the residual's moving part weighs 4x its static part (motion_weight 4)",
        {"motion_weight": 4.0},
        {},
    ),
    "dropout": ("dropout 0.1 in the transformer", {}, {"dropout": 0.1}),
    "temporal_prior": (
        "the Gaussian part over whole sequences, a variance per temporal frequency",
        {"temporal_prior": True},
        {},
    ),
    "temporal_prior_v": (
        "the temporal prior, the network predicting v (Salimans & Ho 2022)",
        {"temporal_prior": True, "prediction": "v"},
        {},
    ),
    "temporal_prior_x4": (
        "the temporal prior and 4x the steps (the shipped recipe)",
        {"temporal_prior": True, "steps_factor": 4},
        {},
    ),
    "weight_decay": ("weight decay 0.05 (AdamW)", {"weight_decay": 0.05}, {}),
}
# the stored table's rows (issue 58); the other VARIANTS (issue 43's) run with --only
TABLE_ROWS = (
    "baseline",
    "x4",
    "crowd",
    "world_faces",
    "motion_weight",
    "dropout",
    "temporal_prior",
    "temporal_prior_x4",
)
REGIONS = metrics.AMPLITUDE_REGIONS
READERS = evaluation.ARCHITECTURES
# the held-out loss read at this step (of T = 2000) in the table; the curves hold all
LOSS_TIME = 200
COLUMNS = (
    ["row", "change", "training steps"]
    + [
        c
        for r in REGIONS
        for q in evaluation.POPULATION_PERCENTILES
        for c in (f"{r} p{q} gap (mm)", "95 % interval")
    ]
    + [
        c
        for reader in READERS
        for c in (
            f"label TV ({reader})",
            f"label TV, real sets' p95 ({reader})",
            f"largest share / reference ({reader})",
            f"largest share, real sets' p95 ({reader})",
        )
    ]
    + [
        f"loss at t = {LOSS_TIME}, {split}"
        for split in ("training split", "new takes", "new people")
    ]
    + ["training seconds", "sampling seconds"]
)


def run_dir():
    return config.cache_dir() / "denoiser_ablation"


def recipe_for(name, dataset, steps):
    """The recipe of row ``name``: the shipped denoiser's with the row's change, for
    ``steps`` steps."""
    _, settings, architecture = VARIANTS[name]
    settings = {**BEFORE, **settings}
    steps *= settings.pop("steps_factor", 1)
    chosen = training.settings_for(
        "denoiser", **{"dataset": dataset, "steps": steps, **settings}
    )
    model_config = None
    if architecture:
        model_config = DenoiserConfig(
            num_diffusion_steps=chosen.num_diffusion_steps,
            schedule=chosen.schedule,
            prediction=chosen.prediction,
            prior_length=chosen.num_frames if chosen.temporal_prior else 0,
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
    parser.add_argument(
        "--dataset", default="coma", choices=list(config.REFERENCE_POPULATIONS)
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=6000,
        help="training steps of a row (a quarter of the recipe's)",
    )
    parser.add_argument(
        "--only",
        nargs="+",
        choices=list(VARIANTS),
        help=f"these rows (default: the table's, {', '.join(TABLE_ROWS)})",
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
    parser.add_argument("--n", type=int, default=64, help="samples per seed")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument(
        "--renoise",
        type=int,
        default=0,
        metavar="N",
        help="also hand N sequences of new people to the chains of --renoise-rows at"
        " the steps of RENOISE_TIMES (stored as NAME_renoise; 0: not)",
    )
    parser.add_argument(
        "--renoise-rows",
        nargs="+",
        choices=list(VARIANTS),
        default=["x4", "temporal_prior_x4"],
        help="the rows --renoise measures (default: the two full-length recipes)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)
    if args.save and args.train_only:
        parser.error("--train-only measures nothing: it cannot --save")
    names = args.only or list(TABLE_ROWS)
    t_start = time.perf_counter()
    stems = {name: trained(name, args.dataset, args.steps) for name in names}
    if args.train_only:
        return
    splits = {
        "training split": data.load_dataset(args.dataset, "train"),
        "new takes": data.load_dataset(config.NEW_TAKES[args.dataset], "train"),
        "new people": data.load_dataset(
            config.REFERENCE_POPULATIONS[args.dataset], "test"
        ),
    }
    rows, curves, buckets = [], [], []
    for name in names:
        row, meta = measured(name, stems[name], args, splits)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if "held_out" not in meta["history"]:  # a copy of the shipped checkpoint
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
            checkpoints=[f"ic_{args.dataset}_I", f"ic_{args.dataset}_I_cnn"],
            seeds=args.seeds,
            n=args.n,
            steps=[args.sample_steps],
            wall_time_s=time.perf_counter() - t_start,
        )
        path = results.save_result(
            args.save,
            f"Denoiser ablations ({args.dataset}) against a reference population,"
            f" {args.steps} training steps a row (x4, x8: 4 and 8 times)",
            COLUMNS,
            rows,
            run,
            notes=(
                f"each row: the recipe before issue 58 (a Gaussian part per frame) with"
                f" one change, {args.steps} steps (x4,"
                f" x8: 4 and 8 times as many), batch 64, seed 0; {args.n} samples for"
                f" each of the seeds {args.seeds} pooled, at {args.sample_steps}"
                " respaced steps. Amplitude gaps: generated minus the reference"
                " population (coma_people, 50 new people), 95 % interval by"
                " metrics.population_gap (samples resampled, the reference by person);"
                " label mix read by the IC (lstm) and a temporal CNN (cnn) beside the"
                " 95th percentile of real sets of the same size"
                " (metrics.label_mix_gap). Loss: evaluation.denoising_loss at"
                f" t = {LOSS_TIME} on the training split, on new takes of its people"
                " (coma_retakes train) and on the reference population. Training"
                " seconds as each run recorded them (runs side by side with one"
                " thread each)"
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
    if args.renoise:
        people = splits["new people"]
        chained = [
            r
            for name in args.renoise_rows
            for r in renoised(name, trained(name, args.dataset, args.steps), people,
                              args.renoise, args.sample_steps)
        ]
        for r in chained:
            print(json.dumps(r), flush=True)
        if args.save:
            path = results.save_result(
                args.save + "_renoise",
                f"Where along the chain the amplitude is lost ({args.dataset}): new"
                " people's sequences handed to each row's chain at step t",
                RENOISE_COLUMNS,
                chained,
                run,
                notes=(
                    f"{args.renoise} sequences of the reference population noised to"
                    " x_t (Eq. 6) and denoised by the rest of the chain"
                    f" ({args.sample_steps} respaced steps; t the nearest step's"
                    " paper step); mouth-opening gaps against the whole population,"
                    " 95 % intervals by metrics.population_gap. Slow variance: the"
                    " variance over sequences of each coordinate's mean over the"
                    f" frames, summed, less the noise's, in {args.renoise} chains run"
                    " from x_T, over the same for the people's x_t"
                ),
            )
            print(f"saved {path}")


# the paper steps t at which real sequences are handed to a row's chain (--renoise)
RENOISE_TIMES = (200, 400, 800, 1200, 1600, 2000)
RENOISE_COLUMNS = [
    "row",
    "t",
    "abar_t",
    "mouth opening p50 gap (mm)",
    "95 % interval",
    "mouth opening p90 gap (mm)",
    "95 % interval",
    "slow variance of x_t, generated / people's",
]


@torch.no_grad()
def renoised(name, stem, people, n, sample_steps, seed=0):
    """Where along the chain a row's amplitude is lost: rows of RENOISE_COLUMNS.

    For each t of RENOISE_TIMES (the chain's nearest step), ``n`` sequences of the
    reference population are noised to x_t (Eq. 6) and the rest of the chain is run
    from there (SDEdit); their mouth openings' median and 90th percentile minus the
    population's, with intervals (metrics.population_gap).  A chain that reproduces
    the data keeps the people's amplitudes from every t.  Beside it, how much of the
    sequences' slowest part the chain itself has built by t: the variance over samples
    of each coordinate's mean over the frames, beyond the noise's own, in ``n`` chains
    run from x_T, over the same in the people's x_t (None where the people's stands
    less than 5 standard errors of the noise's above it, t >= about 1200)."""
    denoiser = tasks.load_denoiser(str(stem))
    chain = denoiser.chain_for(tasks.Unconditional(steps=sample_steps))
    keep = np.random.default_rng(seed).choice(len(people), n, replace=False)
    x0 = torch.as_tensor(denoiser.to_model(people.landmarks[keep])).float()
    steps = {
        t: int(np.abs(np.asarray(chain.timesteps[1:]) - t).argmin()) + 1
        for t in RENOISE_TIMES
    }
    recorded = {}

    def record(k, x, out):  # x is x_{k-1}: the chain's state at step k - 1
        if k - 1 in steps.values():
            recorded[k - 1] = x.clone()

    generator = torch.Generator().manual_seed(seed)
    chain.sample(denoiser.model, tuple(x0.shape), seed=seed + 1, callback=record,
                 progress=False)
    reference = metrics.amplitudes(people.landmarks)["mouth opening"]
    rows = []
    for t, k in steps.items():
        abar = float(chain.alphas_bar[k - 1])
        noise = torch.randn(x0.shape, generator=generator)
        xt = abar**0.5 * x0 + (1 - abar) ** 0.5 * noise
        out = chain.run(denoiser.model, xt, seed=seed + 2,
                        steps=chain.schedule(start=k), progress=False)
        mouth = metrics.amplitudes(denoiser.to_mm(out))["mouth opening"]
        gaps = [
            metrics.population_gap(mouth, reference, people.subjects,
                                   lambda v, q=q: np.percentile(v, q), seed=seed)
            for q in evaluation.POPULATION_PERCENTILES
        ]
        frames = x0.shape[1]
        noise = (1 - abar) * x0[0, 0].numel() / frames  # the noise's share, summed

        def slow(x):  # the means over the frames' variance, beyond the noise's
            return float(x.double().mean(1).var(0).sum()) - noise

        # only where the people's slow part stands out of the noise's sampling spread
        generated, real = recorded.get(k), slow(xt)
        ratio = (
            None
            if generated is None or real < 5 * noise * (2 / n) ** 0.5
            else slow(generated) / real
        )
        rows.append(
            [name, int(chain.timesteps[k]), abar]
            + [v for gap, interval in gaps for v in (float(gap), list(interval))]
            + [ratio]
        )
    return rows


def measured(name, stem, args, splits):
    """(table row, checkpoint metadata) of row ``name`` trained at ``stem``: its samples
    measured by the population protocol, or the measurement a run with the same sample
    settings stored beside the checkpoint (``<stem>.row.json``; the checkpoint's sha256
    keys it)."""
    denoiser = tasks.load_denoiser(str(stem))
    meta = denoiser.meta
    key = {"sha256": meta["sha256"], "n": args.n, "seeds": args.seeds,
           "sample_steps": args.sample_steps}
    cache = Path(str(stem) + ".row.json")
    if cache.exists() and json.loads(cache.read_text())["key"] == key:
        row = json.loads(cache.read_text())["row"]
        return [name, VARIANTS[name][0], *row[2:]], meta  # the change as described now
    t0 = time.perf_counter()
    x = np.concatenate(
        [
            tasks.unconditional(
                args.n, steps=args.sample_steps, seed=s, denoiser=denoiser,
                progress=False,
            )
            for s in args.seeds
        ]
    )
    sampling = time.perf_counter() - t0
    gap = evaluation.population_gap(x, args.dataset, READERS)
    losses = [
        evaluation.denoising_loss(denoiser, split.landmarks, (LOSS_TIME,))[LOSS_TIME]
        for split in splits.values()
    ]
    row = _row(name, meta["training"]["steps"], gap, losses, meta.get("wall_time_s"),
               sampling)
    row = json.loads(json.dumps(row, default=lambda v: v.tolist()))  # numpy -> Python
    cache.write_text(json.dumps({"key": key, "row": row}))
    return row, meta


def _row(name, steps, gap, losses, training_seconds, sampling_seconds):
    amplitudes = [
        v
        for r in REGIONS
        for q in evaluation.POPULATION_PERCENTILES
        for v in (gap["amplitudes"][r][f"p{q}"][0], list(gap["amplitudes"][r][f"p{q}"][1]))
    ]
    mix = [
        v
        for reader in READERS
        for key in ("tv", "tv_real", "max_ratio", "max_ratio_real")
        for v in (gap["label_mix"][reader][key],)
    ]
    return (
        [name, VARIANTS[name][0], steps]
        + amplitudes
        + mix
        + losses
        + [training_seconds, sampling_seconds]
    )


if __name__ == "__main__":
    main()

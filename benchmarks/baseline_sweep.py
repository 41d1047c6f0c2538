"""The Table 1 baselines' tuning sweep: each candidate setting trained at a fraction of
its budget and scored.

Usage: python benchmarks/baseline_sweep.py [--budget 0.25] [--per-label 20] [--only 0 3]
[--save NAME]

Each candidate (``CANDIDATES``: the recipe's defaults, facelib/training/settings.py, with some
settings changed) is trained on the coma training split for ``--budget`` times its
recipe's steps, then generates ``--per-label`` sequences of every label.  The type-I IC
scores them: accuracy and FID with 95 % bootstrap intervals, diversity, and "motion",
the mean over sequences of the largest landmark displacement from the first frame (mm).
The real test sequences are the first row.  ``--only`` runs some candidates (by index);
with ``--save`` the stored table is rewritten after every candidate, replacing just the
rows this run measured.

The rule that picks a setting is the book's (chapter 06): the best accuracy - 2 FID.
The picks go into training.ActorTraining and training.Motion3DGANTraining and are then
trained at the full budget:

    python benchmarks/baseline_sweep.py --save baseline_sweep

(12 candidates at a quarter of the budget: about 3 core-hours with one torch thread.)
"""

import argparse
import time

import numpy as np

from facelib import baselines, evaluation, data, results, training

COLUMNS = [
    "candidate",
    "settings",
    "Acc (%)",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "diversity",
    "motion (mm)",
    "training steps",
    "training (s)",
]
CANDIDATES = [  # (row name, model, settings changed from the recipe's defaults)
    ("ACTOR, KL 1e-3 (world 1's recipe)", "actor", {"kl_weight": 1e-3}),
    ("ACTOR, KL 1e-2", "actor", {"kl_weight": 1e-2}),
    ("ACTOR, KL 3e-2", "actor", {"kl_weight": 3e-2}),
    ("ACTOR, KL 1e-4", "actor", {"kl_weight": 1e-4}),
    (
        "Motion3DGAN, recipe",
        "motion3dgan",
        {"lr": 1e-4},
    ),  # the Motion3DGAN paper's recipe (world 1's)
    ("Motion3DGAN, lr 2e-4", "motion3dgan", {"lr": 2e-4}),
    ("Motion3DGAN, smoothing 2 frames", "motion3dgan", {"smoothing": 2.0}),
    ("Motion3DGAN, 3 critic steps", "motion3dgan", {"critic_steps": 3}),
    (
        "Motion3DGAN, lr 5e-4",
        "motion3dgan",
        {"lr": 5e-4},
    ),  # world 2: the rate is what moved it
    ("Motion3DGAN, lr 1e-3", "motion3dgan", {"lr": 1e-3}),
    ("Motion3DGAN, lr 2e-3", "motion3dgan", {"lr": 2e-3}),
    ("Motion3DGAN, lr 5e-3", "motion3dgan", {"lr": 5e-3}),
]


def motion(x):
    """Mean over sequences of the largest landmark displacement from the first frame
    (mm)."""
    return float(np.linalg.norm(x - x[:, :1], axis=-1).max(axis=(1, 2)).mean())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--budget",
        type=float,
        default=0.25,
        help="fraction of each recipe's steps (default 0.25)",
    )
    parser.add_argument(
        "--per-label",
        type=int,
        default=20,
        help="generated sequences per label (default 20)",
    )
    parser.add_argument(
        "--only", type=int, nargs="+", default=None, help="candidates to run, by index"
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    if not 0 < args.budget <= 1:
        parser.error(f"--budget must be in (0, 1], got {args.budget}")
    chosen = range(len(CANDIDATES)) if args.only is None else args.only
    bad = [i for i in chosen if not 0 <= i < len(CANDIDATES)]
    if bad:
        parser.error(
            f"--only takes candidate indices 0..{len(CANDIDATES) - 1}, got {bad}"
        )
    t_start = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "I")
    test = data.load_dataset("coma", "test")
    labels = [name for name in test.label_names for _ in range(args.per_label)]
    targets = np.array([test.label_names.index(name) for name in labels])

    def scored(name, settings, x, y, steps, seconds):
        s = ev.score(x, y, intervals=True)
        return [
            name,
            settings,
            s["accuracy"],
            list(s["accuracy_ci"]),
            s["fid"],
            list(s["fid_ci"]),
            s["diversity"],
            motion(x),
            steps,
            seconds,
        ]

    def save(rows):
        """Store the table now (after every candidate: an interrupted sweep keeps what
        it measured), merged with the stored rows of the candidates this run does not
        measure."""
        merged, provenance = results.merged_rows(args.save, rows)
        results.save_result(
            args.save,
            "Table 1 baselines: tuning sweep (coma, a fraction of the budget)",
            COLUMNS,
            merged,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=["ic_coma_I"],
                seeds=[0],
                n=len(labels),
                steps=[],
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"budget {args.budget} of each recipe's steps; {args.per_label}"
                " sequences per label; rows of candidates this run did not measure are"
                " those of earlier runs (the commit, date and wall time above are the"
                " last run's; row_provenance names each row's run)"
            ),
            row_provenance=provenance,
        )

    rows = [
        scored("real test sequences", "", test.landmarks, test.targets("I"), 0, 0.0)
    ]
    print(rows[0], flush=True)
    for i in chosen:
        name, model_name, changed = CANDIDATES[i]
        defaults = training.settings_for(model_name, **changed)
        steps = max(1, round(defaults.steps * args.budget))
        recipe = training.recipe(model_name, **changed, steps=steps)
        t0 = time.perf_counter()
        model, _ = training.fit(recipe, progress=False)
        seconds = time.perf_counter() - t0
        model.eval().label_names = (
            test.label_names
        )  # as baselines.load_baseline sets it
        x = baselines.generate(model, labels, seed=0)
        rows.append(
            scored(name, str(changed or "defaults"), x, targets, steps, seconds)
        )
        print(rows[-1], flush=True)
        if args.save:
            save(rows)


if __name__ == "__main__":
    main()

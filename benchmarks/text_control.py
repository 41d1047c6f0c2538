"""Time text control (Alg. 2) for 64 sequences and score them; print a table.

Usage: python benchmarks/text_control.py [--n 64] [--steps 2000 200 100] [--lr R]
[--enriched]
                                         [--head-input x_t x0_hat] [--score cosine
                                         contrastive] [--particles 1 4] [--split
                                         held_out] [--vocabulary] [--setting LAMBDA RATE
                                         ...] [--no-baselines] [--save NAME]
The n sequences cycle through the raw texts of the 18 labels of "coma+bu" (the raw-text
task of §5.2, type-I IC), or with --enriched through the enriched sentences of the 36
(label, order) classes ("from the neutral face to X" / "from X to the neutral face",
type-S IC).  For each number of reverse steps (2000 = the paper's T; fewer = respaced)
it prints the wall time, the time per step, and the IC accuracy and FID of the generated
sequences (FID against the training split, from n sequences: compare rows with each
other, not with tables computed from another n), and the Adagrad rate used (default:
tasks.text_lr, scaled with the number of steps; --lr fixes it).  --head-input lists what
the text head reads (x_t: Alg. 2; x0_hat: the denoiser's estimate, appendix A1, section
2), --score the score Alg. 2 climbs (cosine: Eq. 10; contrastive: the head's
   log-probability of the text, appendix A1, section 3; it reads x_t only, so it is run
   with x_t), --particles the numbers K of
best-of-K chains (appendix A1, section 4).  --split takes the texts from another split
of facelib/descriptions.py (held_out, blind_held_out: the n sequences cycle through the
classes, then through each class's phrasings or sentences), and --vocabulary adds rows
of the contrastive score matching against the vocabulary (appendix A1, section 6).  The
lambda is text_control's default for each score; --setting LAMBDA RATE (repeatable) runs
the guided rows at these lambdas and Adagrad rates instead (a rate at
config.TEXT_LR_REFERENCE_STEPS = 100 steps, scaled to each number of steps as
tasks.text_lr scales its default): chapter 06 section 4 and appendix A1 section 3 sweep
them.  Also timed: the MotionCLIP-style baseline (one decoder pass) and decoder + DDPM
(not in the paper, appendix A1 section 5: the baseline's sequence re-noised to
config.DECODER_START and denoised);
--no-baselines leaves them out.  Every Acc and FID comes with its 95 % bootstrap
  interval over the n
sequences (Evaluator.score(intervals=True)); --save NAME also writes the table to
results/NAME.json (facelib.results.save_result: the command, commit, checkpoints'
sha256, seeds, n, wall time).

Full-scale commands of chapter 06 (wall times with one torch thread, 2026-12-03; the
chapter runs smaller versions and shows these stored tables):
  python benchmarks/text_control.py --n 72 --steps 100 --no-baselines --save
  text_sweep_cosine \
      --setting 0.01 0.01 --setting 0.01 0.1 --setting 0.001 0.03 --setting 0.001 0.1
        --setting 0.001 0.2 \
      --setting 0.0003 0.1 --setting 0.0003 0.2 --setting 0.0003 0.4 --setting 0.0001 0.2   # section 4, 8 min
  python benchmarks/text_control.py --n 72 --steps 100 --enriched --score contrastive
  --no-baselines \
      --setting 0.0001 0.2 --setting 0.001 0.1 --setting 0.01 0.042 --setting 0.01 0.06
        \
      --save text_sweep_contrastive                                                     # appendix A1, 4 min
  python benchmarks/text_control.py --n 409 --steps 100 --score cosine contrastive --save text_table2_raw   # 12 min
  python benchmarks/text_control.py --n 409 --steps 100 --enriched --score cosine
  contrastive --particles 1 4 \
      --save text_table2_enriched                                                       # 53 min
"""

import argparse
import itertools
import os
import time

import numpy as np
import torch

from facelib import (
    baselines,
    config,
    data,
    descriptions,
    evaluation,
    results,
    tasks,
    text,
)

DATASET = config.TEXT_DATASET
COLUMNS = [
    "method",
    "steps",
    "lambda",
    "lr",
    "seconds",
    "Acc %",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "MM",
]


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 200, 100])
    parser.add_argument(
        "--lr",
        type=float,
        default=None,
        help="Adagrad rate for every row (default: tasks.text_lr)",
    )
    parser.add_argument(
        "--enriched", action="store_true", help="the enriched-text task (type-S IC)"
    )
    parser.add_argument(
        "--head-input", nargs="+", default=["x_t"], choices=list(config.HEAD_INPUTS)
    )
    parser.add_argument(
        "--score", nargs="+", default=["cosine"], choices=list(config.TEXT_SCORES)
    )
    parser.add_argument(
        "--particles",
        type=int,
        nargs="+",
        default=[1],
        help=(
            "best-of-K (appendix A1 section 4; K > 1 runs with max_time ="
            " config.PARTICLE_MAX_TIME)"
        ),
    )
    parser.add_argument(
        "--split",
        default="train",
        choices=list(descriptions.SPLITS),
        help="the descriptions' split the texts come from (default: train)",
    )
    parser.add_argument(
        "--vocabulary",
        action="store_true",
        help=(
            "also run the contrastive score with vocabulary=True (appendix A1,"
            " section 6)"
        ),
    )
    parser.add_argument(
        "--setting",
        type=float,
        nargs=2,
        action="append",
        metavar=("LAMBDA", "RATE"),
        help=(
            "run the guided rows at this lambda and Adagrad rate (at 100 steps);"
            " repeatable"
        ),
    )
    parser.add_argument(
        "--no-baselines",
        action="store_true",
        help="leave out the MotionCLIP-style and decoder + DDPM rows",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    kind = "S" if args.enriched else "I"
    ev = evaluation.load_evaluator(DATASET, kind)
    head, denoiser = tasks.load_text_head(DATASET), tasks.load_denoiser(
        f"denoiser_{DATASET}"
    )
    encoder = text.get_encoder()
    classes = [ev.class_names[i % len(ev.class_names)] for i in range(args.n)]

    def text_of(i, c):  # the class's (i // classes)-th text of the split, cycling
        options = (
            descriptions.enriched_texts(*c.split(), args.split)
            if args.enriched
            else descriptions.phrasings(c, args.split)
        )
        return options[(i // len(ev.class_names)) % len(options)]

    texts = [text_of(i, c) for i, c in enumerate(classes)]
    targets = np.array([ev.class_index(c) for c in classes])
    encoder.encode(texts)  # load the encoder once, outside the timings
    task = "enriched (IC S)" if args.enriched else "raw (IC I)"
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, dataset:"
        f" {DATASET}, n = {args.n}, lambda {tasks.text_guidance_weight('cosine')}"
        f" (cosine) / {tasks.text_guidance_weight('contrastive')} (contrastive), task"
        f" {task}, {args.split} texts"
    )
    print(
        f"{'method':<38}{'steps':>6}{'lambda':>8}{'lr':>8}{'seconds':>9}{'ms/step':>9}{'Acc %':>7}{'interval':>14}"
        f"{'FID':>8}{'interval':>18}{'MM':>7}"
    )
    rows = []

    def row(name, make, targets_, steps=None, lam=None, lr=None):
        """Time make(), score its sequences with 95 % intervals, print and keep the
        row."""
        t0 = time.perf_counter()
        x = make()
        dt = (
            time.perf_counter() - t0
            if steps is not None or name.startswith("MotionCLIP")
            else 0.0
        )
        s = ev.score(x, targets_, intervals=True)
        rows.append(
            [
                name,
                steps or 0,
                lam if lam is not None else "",
                lr if lr is not None else "",
                round(dt, 2),
                s["accuracy"],
                list(s["accuracy_ci"]),
                s["fid"],
                list(s["fid_ci"]),
                s["multimodality"],
            ]
        )
        acc_ci, fid_ci = "[{:.1f}, {:.1f}]".format(
            *s["accuracy_ci"]
        ), "[{:.2f}, {:.2f}]".format(*s["fid_ci"])
        per_step = f"{1e3 * dt / steps:.1f}" if steps else ""
        print(
            f"{name:<38}{steps or '':>6}{'' if lam is None else f'{lam:g}':>8}{'' if lr is None else f'{lr:.3g}':>8}"
            f"{dt:>9.1f}{per_step:>9}{s['accuracy']:>7.1f}{acc_ci:>14}{s['fid']:>8.2f}{fid_ci:>18}"
            f"{s['multimodality']:>7.2f}",
            flush=True,
        )

    test = data.load_dataset(DATASET, "test")
    pick = np.random.default_rng(0).choice(
        len(test), min(args.n, len(test)), replace=False
    )
    row("GT (test sequences)", lambda: test.landmarks[pick], test.targets(kind)[pick])
    if not args.no_baselines:
        model = baselines.load_baseline("motionclip", DATASET)
        row(
            "MotionCLIP-style",
            lambda: baselines.generate_from_text(model, texts, encoder=encoder),
            targets,
        )
        for steps in (
            args.steps
            # not in the paper: the decoder's sequence re-noised and denoised (appendix A1)
        ):
            row(
                f"decoder + DDPM (t0={config.DECODER_START})",
                lambda: tasks.decoder_then_diffusion(
                    texts,
                    args.n,
                    steps=steps,
                    seed=0,
                    denoiser=denoiser,
                    decoder=model,
                    progress=False,
                ),
                targets,
                steps,
            )
    vocabularies = [False, True] if args.vocabulary else [False]
    settings = [tuple(s) for s in args.setting] if args.setting else [None]
    for steps, head_input, score, k, vocabulary, setting in itertools.product(
        args.steps, args.head_input, args.score, args.particles, vocabularies, settings
    ):
        if (
            score == "contrastive"
            and head_input != "x_t"
            or vocabulary
            and score != "contrastive"
        ):
            # the contrastive score reads x_t only; only it matches a vocabulary
            continue
        lam = tasks.text_guidance_weight(score) if setting is None else setting[0]
        lr = (
            args.lr
            if args.lr is not None
            else (
                tasks.text_lr(steps, score=score)
                if setting is None
                else tasks.step_scaled_lr(
                    setting[1], config.TEXT_LR_REFERENCE_STEPS, steps, power=1.0
                )
            )
        )
        name = (
            f"ours, {score}, {head_input}"
            + (f", K={k}" if k > 1 else "")
            + (", vocab." if vocabulary else "")
        )
        row(
            name,
            lambda: tasks.text_control(
                texts,
                args.n,
                steps=steps,
                guidance_weight=lam,
                lr=lr,
                head_input=head_input,
                score=score,
                vocabulary=vocabulary,
                particles=k,
                max_time=config.PARTICLE_MAX_TIME if k > 1 else None,
                seed=0,
                head=head,
                denoiser=denoiser,
                progress=False,
            ),
            targets,
            steps,
            lam,
            lr,
        )
    if args.save:
        used = [f"denoiser_{DATASET}", f"guide_{DATASET}_text", f"ic_{DATASET}_{kind}"]
        path = results.save_result(
            args.save,
            title=(
                f"text control (Alg. 2), {task}, {args.split} texts, dataset {DATASET}"
            ),
            columns=COLUMNS,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=used
                + ([] if args.no_baselines else [f"motionclip_{DATASET}"]),
                seeds=[0],
                n=args.n,
                steps=sorted(set(args.steps)),
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                "texts cycle through the classes of the IC (then each class's texts of"
                " the split); GT: n test sequences picked with numpy seed 0; sampler"
                " seed 0; lr: the Adagrad rate at that number of steps; K > 1 with"
                " max_time = config.PARTICLE_MAX_TIME; FID against the training split"
                " from n sequences; intervals: 95 % bootstrap over the sequences"
                " (Evaluator.score(intervals=True)); seconds: wall time of the row"
            ),
        )
        print("stored", path)


if __name__ == "__main__":
    main()

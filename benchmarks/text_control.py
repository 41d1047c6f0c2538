"""Time text control (Alg. 2) for 64 sequences and score them; print a table.

Usage: python benchmarks/text_control.py [--n 64] [--steps 2000 200 100] [--lr R] [--enriched]
                                         [--head-input x_t x0_hat] [--score cosine contrastive]
                                         [--particles 1 4] [--split held_out] [--vocabulary]
The n sequences cycle through the raw texts of the 18 labels of "coma+bu" (the raw-text task of
§5.2, type-I IC), or with --enriched through the enriched sentences of the 36 (label, order) classes
("from the neutral face to X" / "from X to the neutral face", type-S IC).  For each number of reverse
steps (2000 = the paper's T; fewer = respaced) it prints the wall time, the time per step, and the
IC accuracy and FID of the generated sequences (FID against the training split, from n sequences:
compare rows with each other, not with tables computed from another n), and the Adagrad rate used
(default: tasks.text_lr, scaled with the number of steps; --lr fixes it).  --head-input lists what
the text head reads (x_t: Alg. 2; x0_hat: the denoiser's estimate, chapter 06 section 8), --score
the score Alg. 2 climbs (cosine: Eq. 10; contrastive: the head's log-probability of the text,
chapter 06 section 10; it reads x_t only, so it is run with x_t), --particles the numbers K of
best-of-K chains (chapter 06 section 11).  --split takes the texts from another split of
facelib/descriptions.py (held_out, blind_held_out: the n sequences cycle through the classes, then
through each class's phrasings or sentences), and --vocabulary adds rows of the contrastive score
matching against the vocabulary (chapter 06 section 12).  The lambda is text_control's
default for each score.  Also
timed: the MotionCLIP-style baseline (one decoder pass) and decoder + DDPM (not in the paper,
chapter 06 section 9: the baseline's sequence re-noised to tasks.DECODER_START and denoised).
"""
import argparse
import itertools
import os
import time

import numpy as np
import torch

from facelib import baselines, data, descriptions, evaluation, tasks, text

DATASET = tasks.TEXT_DATASET


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 200, 100])
    parser.add_argument("--lr", type=float, default=None, help="Adagrad rate for every row (default: tasks.text_lr)")
    parser.add_argument("--enriched", action="store_true", help="the enriched-text task (type-S IC)")
    parser.add_argument("--head-input", nargs="+", default=["x_t"], choices=list(tasks.HEAD_INPUTS))
    parser.add_argument("--score", nargs="+", default=["cosine"], choices=list(tasks.TEXT_SCORES))
    parser.add_argument("--particles", type=int, nargs="+", default=[1],
                        help="best-of-K (chapter 06 section 11; K > 1 runs with max_time = tasks.PARTICLE_MAX_TIME)")
    parser.add_argument("--split", default="train", choices=list(descriptions.SPLITS),
                        help="the descriptions' split the texts come from (default: train)")
    parser.add_argument("--vocabulary", action="store_true",
                        help="also run the contrastive score with vocabulary=True (chapter 06 section 12)")
    args = parser.parse_args()
    kind = "S" if args.enriched else "I"
    ev = evaluation.load_evaluator(DATASET, kind)
    head, denoiser = tasks.load_text_head(DATASET), tasks.load_denoiser(f"denoiser_{DATASET}")
    encoder = text.get_encoder()
    classes = [ev.class_names[i % len(ev.class_names)] for i in range(args.n)]

    def text_of(i, c):  # the class's (i // classes)-th text of the split, cycling
        options = (descriptions.enriched_texts(*c.split(), args.split) if args.enriched
                   else descriptions.phrasings(c, args.split))
        return options[(i // len(ev.class_names)) % len(options)]
    texts = [text_of(i, c) for i, c in enumerate(classes)]
    targets = np.array([ev.class_index(c) for c in classes])
    encoder.encode(texts)  # load the encoder once, outside the timings
    task = "enriched (IC S)" if args.enriched else "raw (IC I)"
    print(f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, dataset: {DATASET}, "
          f"n = {args.n}, lambda {tasks.text_guidance_weight('cosine')} (cosine) / {tasks.text_guidance_weight('contrastive')} "
          f"(contrastive), task {task}, {args.split} texts")
    print(f"{'method':<38}{'steps':>6}{'seconds':>10}{'ms/step':>9}{'Acc %':>8}{'FID':>8}{'lr':>8}")
    test = data.load_dataset(DATASET, "test")
    pick = np.random.default_rng(0).choice(len(test), min(args.n, len(test)), replace=False)
    gt = ev.score(test.landmarks[pick], test.targets(kind)[pick])
    print(f"{'GT (test sequences)':<38}{'':>6}{'':>10}{'':>9}{gt['accuracy']:>8.1f}{gt['fid']:>8.2f}")
    model = baselines.load_baseline("motionclip", DATASET)
    t0 = time.perf_counter()
    x = baselines.generate_from_text(model, texts, encoder=encoder)
    dt = time.perf_counter() - t0
    s = ev.score(x, targets)
    print(f"{'MotionCLIP-style':<38}{'':>6}{dt:>10.2f}{'':>9}{s['accuracy']:>8.1f}{s['fid']:>8.2f}", flush=True)
    for steps in args.steps:  # not in the paper: the decoder's sequence re-noised and denoised (chapter 06 section 9)
        t0 = time.perf_counter()
        x = tasks.decoder_then_diffusion(texts, args.n, steps=steps, seed=0, denoiser=denoiser, decoder=model,
                                         encoder=encoder, progress=False)
        dt = time.perf_counter() - t0
        s = ev.score(x, targets)
        print(f"{f'decoder + DDPM (t0={tasks.DECODER_START})':<38}{steps:>6}{dt:>10.1f}{'':>9}"
              f"{s['accuracy']:>8.1f}{s['fid']:>8.2f}", flush=True)
    vocabularies = [False, True] if args.vocabulary else [False]
    for steps, head_input, score, k, vocabulary in itertools.product(args.steps, args.head_input, args.score,
                                                                     args.particles, vocabularies):
        if score == "contrastive" and head_input != "x_t" or vocabulary and score != "contrastive":
            continue  # the contrastive score reads x_t only; only it matches a vocabulary
        lr = tasks.text_lr(steps, score=score) if args.lr is None else args.lr
        t0 = time.perf_counter()
        x = tasks.text_control(texts, args.n, steps=steps, lr=lr, head_input=head_input, score=score,
                               vocabulary=vocabulary, particles=k,
                               max_time=tasks.PARTICLE_MAX_TIME if k > 1 else None, seed=0, head=head,
                               denoiser=denoiser, encoder=encoder, progress=False)
        dt = time.perf_counter() - t0
        s = ev.score(x, targets)
        name = f"ours, {score}, {head_input}" + (f", K={k}" if k > 1 else "") + (", vocab." if vocabulary else "")
        print(f"{name:<38}{steps:>6}{dt:>10.1f}{1e3 * dt / steps:>9.1f}{s['accuracy']:>8.1f}"
              f"{s['fid']:>8.2f}{lr:>8.3g}", flush=True)


if __name__ == "__main__":
    main()

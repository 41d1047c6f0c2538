"""Time label control (Alg. 1) for 64 sequences and score them; print a table.

Usage: python benchmarks/label_control.py [--dataset coma] [--n 64] [--steps 2000 200 100] [--lr 0.03]
The n sequences cycle through the dataset's labels.  For each number of reverse steps (2000 =
the paper's T; fewer = respaced) it prints the wall time, the time per step, and the IC accuracy
and FID of the guided sequences (FID against the training split, from n sequences: compare rows
with each other, not with tables computed from another n).
"""
import argparse
import os
import time

import numpy as np
import torch

from facelib import data, evaluation, tasks


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", default="coma")
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 500, 200, 100])
    parser.add_argument("--lr", type=float, default=None, help="one Adagrad rate for every row (default: tasks.adagrad_lr)")
    args = parser.parse_args()
    ev = evaluation.load_evaluator(args.dataset, "I")
    guide, denoiser = tasks.load_guide(args.dataset), tasks.load_denoiser(f"denoiser_{args.dataset}")
    labels = [ev.class_names[i % len(ev.class_names)] for i in range(args.n)]
    targets = np.array([ev.class_index(y) for y in labels])
    print(f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, dataset: {args.dataset}, "
          f"n = {args.n}, Adagrad lr {tasks.ADAGRAD_LR[args.dataset]} at {tasks.LR_REFERENCE_STEPS} steps, x sqrt({tasks.LR_REFERENCE_STEPS} / steps), lambda 0.01")
    print(f"{'steps':>6}{'seconds':>10}{'ms/step':>9}{'Acc %':>8}{'FID':>8}{'lr':>9}")
    test = data.load_dataset(args.dataset, "test")
    pick = np.random.default_rng(0).choice(len(test), min(args.n, len(test)), replace=False)
    gt = ev.score(test.landmarks[pick], test.targets("I")[pick])
    print(f"{'GT':>6}{'':>10}{'':>9}{gt['accuracy']:>8.1f}{gt['fid']:>8.2f}   ({len(pick)} random test sequences)")
    for steps in args.steps:
        t0 = time.perf_counter()
        lr = tasks.adagrad_lr(args.dataset, steps) if args.lr is None else args.lr
        x = tasks.label_control(labels, args.n, steps=steps, seed=0, guide=guide, denoiser=denoiser, lr=lr, progress=False)
        dt = time.perf_counter() - t0
        s = ev.score(x, targets)
        print(f"{steps:>6}{dt:>10.1f}{1e3 * dt / steps:>9.1f}{s['accuracy']:>8.1f}{s['fid']:>8.2f}{lr:>9.4f}", flush=True)


if __name__ == "__main__":
    main()

"""Time unconditional sampling with the shipped denoiser, and one training step; print a table.

Usage: python benchmarks/sampling.py [--n 64] [--checkpoint denoiser_coma]
Measures 64 sequences of 40 frames at the paper's T = 2000 and respaced to 500/200/100/50 steps,
with the nearest-training-sequence RMSE (median, mm) of the samples as a quality check.
"""
import argparse
import os
import time

import numpy as np
import torch

from facelib import data, tasks
from facelib.metrics import nearest_neighbour_rmse, temporal_roughness
from facelib.train import DenoiserTraining


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--checkpoint", default="denoiser_coma")
    args = parser.parse_args()
    denoiser = tasks.load_denoiser(args.checkpoint)
    train = data.load_dataset(denoiser.meta["training"]["dataset"], "train")
    print(f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, checkpoint: {args.checkpoint}")
    print(f"{'steps':>6}{'seconds':>10}{'ms/step':>9}{'NN RMSE mm':>12}{'roughness':>11}")
    for steps in (2000, 500, 200, 100, 50):
        t0 = time.perf_counter()
        x = tasks.unconditional(args.n, seed=0, steps=steps, denoiser=denoiser, progress=False)
        dt = time.perf_counter() - t0
        nn = np.median(nearest_neighbour_rmse(x, train.landmarks))
        print(f"{steps:>6}{dt:>10.1f}{1e3 * dt / steps:>9.1f}{nn:>12.2f}{temporal_roughness(x):>11.3f}")
    cfg = DenoiserTraining()
    model = denoiser.model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr)
    x0 = torch.as_tensor(denoiser.normalizer.normalize(train.landmarks[:cfg.batch_size]))
    times = []
    for _ in range(6):
        t0 = time.perf_counter()
        loss = denoiser.diffusion.training_loss(model, x0)
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    per_step = np.median(times[1:])
    print(f"training step (batch {cfg.batch_size}, 40 frames): {per_step:.3f} s; the shipped recipe of "
          f"{cfg.steps} steps: {cfg.steps * per_step / 60:.1f} min (target <= 30 min)")


if __name__ == "__main__":
    main()

"""Options that combine (issue 57): filling by DDIM at every eta, and the edit round trip
at both spacings, on held-out coma sequences.

Usage: python benchmarks/options_combine.py [--n 8] [--steps 50] [--eta 0 0.02 0.2 0.5 1]

Prints, for each eta, the mean landmark error (mm) of ``tasks.fill`` on the unknown
frames of FFM masks (sampler DDIM, ``--steps`` steps; the book's reconstruction
guidance); then the mean landmark error (mm) of ``tasks.edit`` with the guidance off
(scale 0, keep None: inversion and regeneration alone; the Edit defaults otherwise) for
the uniform and the trailing spacing.  The first ``--n`` sequences of the test split.
About 30 s with one torch thread at the defaults.
"""

import argparse
import time

import numpy as np
import torch

from facelib import data, tasks
from facelib.inpainting import fill_masks


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=8)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument(
        "--eta", type=float, nargs="+", default=[0.0, 0.02, 0.2, 0.5, 1.0]
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    x = data.load_dataset("coma", "test").landmarks[: args.n].astype(np.float64)
    mask = fill_masks("FFM", args.n, seed=0)
    print(f"fill, DDIM {args.steps} steps, {args.n} sequences (FFM)")
    for eta in args.eta:
        start = time.time()
        out = tasks.fill(
            x, mask, steps=args.steps, sampler="ddim", eta=eta, progress=False
        )
        err = np.linalg.norm(out - x, axis=-1)[~mask].mean()
        seconds = time.time() - start
        print(f"  eta {eta:<5g} unknown frames off by {err:6.2f} mm ({seconds:.0f} s)")
    print(f"edit round trip, guidance off, {args.n} sequences")
    for spacing in ("uniform", "trailing"):
        out = tasks.edit(
            x, "high_smile", scale=0.0, keep=None, spacing=spacing, progress=False
        )
        err = np.linalg.norm(out - x, axis=-1).mean()
        print(f"  {spacing:9s} {err:.3f} mm")


if __name__ == "__main__":
    main()

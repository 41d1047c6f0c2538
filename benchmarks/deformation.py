"""Time the landmark-guided mesh deformation (§3.3) of one 40-frame sequence, and the
whole `animate` pipeline; print tables.

Usage: python benchmarks/deformation.py [--repeats 10] [--no-animate]

Deformation: for each Table 5 method, the median wall time of deforming one neutral mesh
with a 40-frame landmark sequence (one forward pass over the 40 frames; target 0.1 s on
2 cores; the paper: 1.30 s per sequence on its GPU machine).  Shipped checkpoints are
used where present, otherwise a freshly initialised network of the same architecture
(the time does not depend on the weights).  Animate: the stages of ``python -m facelib
animate`` for one label (target: 60 s in default mode), run on a new identity's neutral
face written to a temporary folder.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch

from facelib import deformation
from facelib.face import Face, sample_identity
from facelib.face import template as tpl


def model_for(method):
    try:
        return deformation.load_deformer(method, "identity"), "shipped"
    except FileNotFoundError:
        torch.manual_seed(0)
        return deformation.build_model(method).eval(), "untrained"


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument(
        "--no-animate", action="store_true", help="skip the end-to-end timing"
    )
    args = parser.parse_args()
    neutral = Face(sample_identity(123)).neutral.astype(np.float32)
    landmarks = neutral[tpl.get_template().landmark_index][
        None
    ] + np.random.default_rng(0).normal(0, 1.0, (args.frames, 68, 3)).astype(np.float32)
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, vertices:"
        f" {len(neutral)}, frames: {args.frames}, repeats: {args.repeats}"
    )
    print(
        f"{'method':<22}{'weights':>10}{'parameters':>12}{'s / sequence':>14}{'ms / frame':>12}"
    )
    for method in deformation.METHODS:
        model, origin = model_for(method)
        deformation.deform(neutral, landmarks, model=model)  # warm-up
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            deformation.deform(neutral, landmarks, model=model)
            times.append(time.perf_counter() - t0)
        s = statistics.median(times)
        params = sum(p.numel() for p in model.parameters())
        print(
            f"{deformation.METHOD_NAMES[method]:<22}{origin:>10}{params:>12,}{s:>14.3f}{1e3 * s / args.frames:>12.2f}",
            flush=True,
        )
    if args.no_animate:
        return
    with tempfile.TemporaryDirectory() as tmp:
        mesh = os.path.join(tmp, "neutral.obj")
        subprocess.run(
            [
                sys.executable,
                "-m",
                "facelib",
                "neutral",
                "--seed",
                "123",
                "--out",
                mesh,
            ],
            check=True,
            capture_output=True,
        )
        t0 = time.perf_counter()
        run = subprocess.run(
            [
                sys.executable,
                "-m",
                "facelib",
                "animate",
                "--mesh",
                mesh,
                "--label",
                "high_smile",
                "--out",
                os.path.join(tmp, "out"),
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - t0
        print(
            "\n`python -m facelib animate --label high_smile` (default mode), stages:"
        )
        print(
            "\n".join(line for line in run.stdout.splitlines() if line.startswith("  "))
        )
        print(f"  {'wall clock (with Python start-up and imports)':<12} {wall:7.2f} s")


if __name__ == "__main__":
    main()

"""Time the generation of the synthetic datasets from nothing (no cache) and print a
table.

Usage: python benchmarks/generate_datasets.py [--repeats 3]
Target (issue: foundation): both default datasets (F = 40) in <= 30 s on 2 cores.
"""

import argparse
import os
import time

import numpy as np
import torch

from facelib import config, data


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, repeats:"
        f" {args.repeats}"
    )
    print(
        f"{'dataset':<10}{'frames':>8}{'sequences':>11}{'best s':>9}{'median s':>10}{'seq/s':>9}"
    )
    total = 0.0
    for name, frames in (("coma", 40), ("bu", 40), ("coma", 80), ("coma", (35, 45))):
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            arrays = data.generate(config.DATASETS[name], frames)
            times.append(time.perf_counter() - t0)
        n = len(arrays["labels"])
        if frames == 40:
            total += min(times)
        label = frames if isinstance(frames, int) else f"{frames[0]}-{frames[1]}"
        print(
            f"{name:<10}{label!s:>8}{n:>11}{min(times):>9.2f}{np.median(times):>10.2f}{n / min(times):>9.0f}"
        )
    print(
        f"both default datasets (F = 40): {total:.2f} s (target <= 30 s):"
        f" {'OK' if total <= 30 else 'TOO SLOW'}"
    )


if __name__ == "__main__":
    main()

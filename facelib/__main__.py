"""Command line of the book: ``python -m facelib data`` (later: train, sample, animate, evaluate)."""
from __future__ import annotations

import argparse
import json
import sys
import time

from . import config, data


def _data(args):
    names = list(config.DATASETS) if args.name == "all" else [args.name]
    fingerprints = json.loads(data.FINGERPRINT_FILE.read_text()) if data.FINGERPRINT_FILE.exists() else {}
    status = 0
    for name in names:
        t0 = time.perf_counter()
        arrays = data.build(name, args.frames, rebuild=args.rebuild)
        print(data.summary(name, arrays))
        print(f"ready in {time.perf_counter() - t0:.1f} s: {data.cache_path(name, args.frames)}")
        fp = data.fingerprint(arrays)
        key = f"{name}-F{args.frames}"
        if args.write_fingerprints:
            fingerprints[key] = fp
        elif key in fingerprints:
            same = data.fingerprints_match(fp, fingerprints[key])
            print(f"fingerprint {'matches' if same else 'DIFFERS FROM'} {data.FINGERPRINT_FILE.name}")
            status |= not same
        print()
    if args.write_fingerprints:
        data.FINGERPRINT_FILE.write_text(json.dumps(fingerprints, indent=2, sort_keys=True) + "\n")
        data.CONFIG_FILE.write_text(json.dumps(data.generator_config(), indent=2) + "\n")
        print(f"wrote {data.FINGERPRINT_FILE} and {data.CONFIG_FILE}")
    return status


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m facelib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("data", help="build (or verify) the synthetic dataset caches and print a summary")
    p.add_argument("--name", default="all", choices=["all", *config.DATASETS])
    p.add_argument("--frames", type=int, default=40, help="frames per sequence (default 40, as in the paper)")
    p.add_argument("--rebuild", action="store_true", help="regenerate even if a valid cache exists")
    p.add_argument("--write-fingerprints", action="store_true",
                   help="record the datasets' fingerprints in data/synthetic/fingerprints.json")
    p.set_defaults(func=_data)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        parser.error(str(e))


if __name__ == "__main__":
    sys.exit(main())

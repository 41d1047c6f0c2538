"""Save and load model weights: a state_dict (.pt) beside a JSON with the config (MDM
style).

The JSON records the sha256 of the .pt; loading checks it, so a corrupted or swapped
weight file is reported instead of silently producing garbage.  Loading also checks that
the checkpoint is of the expected kind and that its weights fit the architecture its
config describes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from pathlib import Path

import torch

from . import config


def _sha256(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def checkpoint_paths(name):
    """(weights .pt, metadata .json) of a checkpoint given by name (in data/checkpoints)
    or path stem."""
    stem = Path(name)
    if not stem.parent.parts or str(stem.parent) == ".":
        stem = config.CHECKPOINT_DIR / stem
    stem = stem.with_suffix("") if stem.suffix in (".pt", ".json") else stem
    return stem.with_suffix(".pt"), stem.with_suffix(".json")


NAMED_KINDS = (
    "denoiser",
    "guide",
    "au_regressor",
    "ic",
    "deform",
    "actor",
    "motion3dgan",
    "motionclip",
    "lstm_filler",
)


def checkpoint_name(kind, dataset=None, variant=None, seed=0):
    """The one place checkpoints are named (data/checkpoints/world<N>/NAME.pt):

    denoiser_<dataset>[_<variant>] (variant "var": lengths 35-45, "cfg":
    label-conditional, "var_cfg", "join": reads known frames), guide_<dataset>_<variant>
    (I, S or text),
    ic_<dataset>_<variant> (I or S), au_regressor_<dataset>, <baseline>_<dataset>
    (actor, motion3dgan, motionclip, lstm_filler), deform_<method>_<split>[_seed<k>]
    (``dataset`` the method, ``variant`` the split; seed 0 unnamed)."""
    if kind not in NAMED_KINDS:
        raise ValueError(
            f"unknown checkpoint kind {kind!r}; allowed: {', '.join(NAMED_KINDS)}"
        )
    if kind in ("guide", "ic", "deform") and variant is None:
        raise ValueError(
            f"a {kind} checkpoint's name needs its variant (type or split)"
        )
    name = "_".join(str(part) for part in (kind, dataset, variant) if part)
    return name + (f"_seed{seed}" if seed else "")


def world_fingerprint():
    """The synthetic world this process builds: {"version": config.WORLD, "fingerprint":
    the first 12 hex digits of the sha256 of its committed dataset fingerprints
    (data/synthetic/fingerprints.json)}.
    """
    path = config.SYNTHETIC_DIR / "fingerprints.json"
    digest = (
        hashlib.sha256(path.read_bytes()).hexdigest()[:12] if path.exists() else None
    )
    return {"version": config.WORLD, "fingerprint": digest}


def check_world(meta, name):
    """A checkpoint's metadata must name the world of this process (world 1's
    checkpoints predate the record and name none); a clear error naming both worlds and
    the retrain command if not.
    """
    recorded = meta.get("world", {"version": 1, "fingerprint": None})
    current = world_fingerprint()
    known = None not in (recorded["fingerprint"], current["fingerprint"])
    if recorded["version"] != current["version"]:
        why = (
            f"was trained on world {recorded['version']}, but this process builds world"
            f" {current['version']}"
        )
    elif known and recorded["fingerprint"] != current["fingerprint"]:
        why = (
            f"was trained on world {current['version']}'s datasets as they were"
            f" (fingerprint {recorded['fingerprint']}); they have changed since"
            f" (fingerprint {current['fingerprint']})"
        )
    else:
        return
    raise ValueError(
        f"checkpoint {name} {why}; retrain it (a shipped one: `python -m facelib train"
        f" all --missing --only {Path(name).stem}`)"
    )


def save_checkpoint(name, model, kind, model_config, **metadata):
    """Write ``name``.pt (state_dict) and ``name``.json (kind, config, sha256, world,
    metadata)."""
    pt, js = checkpoint_paths(name)
    pt.parent.mkdir(parents=True, exist_ok=True)
    torch.save({k: v.detach().cpu() for k, v in model.state_dict().items()}, pt)
    meta = {
        "kind": kind,
        "config": model_config,
        "sha256": _sha256(pt),
        "world": world_fingerprint(),
        **metadata,
    }
    js.write_text(json.dumps(meta, indent=1) + "\n")
    return pt, js


# the open recording() blocks: each collects {checkpoint name: sha256} of every load
_RECORDERS = []


@contextlib.contextmanager
def recording():
    """Within the block, every checkpoint loaded is recorded: yields a dict {file stem:
    sha256} that fills as loads happen (what an output names as the checkpoints that
    made it)."""
    used = {}
    _RECORDERS.append(used)
    try:
        yield used
    finally:
        _RECORDERS.remove(used)


def load_checkpoint(name, kind, build):
    """Load a checkpoint: verify its sha256 and kind, build the model with
    ``build(config)``.

    Returns (model in eval mode, metadata dict).  Raises FileNotFoundError if it is
    missing and ValueError if it is corrupted, of another world or kind, or does not fit
    the architecture.
    """
    pt, js = checkpoint_paths(name)
    if not (config.DATA_DIR / "checkpoints").is_dir():
        raise FileNotFoundError(
            "facelib's data folder (data/checkpoints, data/synthetic) is not at"
            f" {config.DATA_DIR}: `pip install .` installs the code only; set"
            " FACELIB_DATA_DIR to the data/ folder of a clone of the book (or install"
            " the clone with `pip install -e .`)"
        )
    if not pt.exists() or not js.exists():
        raise FileNotFoundError(
            f"checkpoint {pt.with_suffix('')} not found (need both .pt and .json); "
            "train it with `python -m facelib train ...`"
        )
    meta = json.loads(js.read_text())
    check_world(meta, pt.name)
    if meta.get("kind") != kind:
        raise ValueError(
            f"checkpoint {pt.name} is a {meta.get('kind')!r} checkpoint, expected"
            f" {kind!r}"
        )
    actual = _sha256(pt)
    if actual != meta.get("sha256"):
        raise ValueError(
            f"checkpoint {pt.name} is corrupted or does not match its metadata: sha256"
            f" {actual[:12]}... != {str(meta.get('sha256'))[:12]}... recorded in"
            f" {js.name}"
        )
    model = build(meta["config"])
    state = torch.load(pt, map_location="cpu", weights_only=True)
    try:
        missing, unexpected = model.load_state_dict(state, strict=False)
    except RuntimeError as e:  # same names, different shapes
        raise ValueError(
            f"checkpoint {pt.name} does not fit a {kind} built from its config: {e}"
        ) from None
    if missing or unexpected:
        raise ValueError(
            f"checkpoint {pt.name} does not fit a {kind} built from its config: "
            f"missing {list(missing)[:5]}, unexpected {list(unexpected)[:5]}"
        )
    for used in _RECORDERS:
        used[pt.stem] = actual
    return model.eval(), meta

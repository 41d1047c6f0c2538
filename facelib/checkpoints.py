"""Save and load model weights: a state_dict (.pt) beside a JSON with the config (MDM
style).

The JSON records the sha256 of the .pt; loading checks it, so a corrupted or swapped
weight file is reported instead of silently producing garbage (a file is hashed once per
process while its path, mtime and size stay the same).  Loading also checks that the
checkpoint is of the expected kind, that the datasets it read have not changed since
(their entries of data/synthetic/fingerprints.json) and that its weights fit the
architecture its config describes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from pathlib import Path

import torch

from . import config
from .files import atomic_write, atomic_write_text


def _sha256(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# {(resolved path, st_mtime_ns, st_size): sha256} of the .pt files whose sha256 matched
# their metadata in this process
_VERIFIED = {}
# a file modified less than this long ago is hashed on every load: a rewrite within the
# filesystem's timestamp granularity could keep both its mtime and its size
_SETTLED_NS = 2 * 10**9


def _checked_sha256(pt, recorded):
    """The sha256 of ``pt``, read from the cache when this file (path, mtime, size) has
    already matched ``recorded`` in this process."""
    st = pt.stat()
    key = (str(pt.resolve()), st.st_mtime_ns, st.st_size)
    if key in _VERIFIED and _VERIFIED[key] == recorded:
        return recorded
    actual = _sha256(pt)
    if actual == recorded and time.time_ns() - st.st_mtime_ns > _SETTLED_NS:
        _VERIFIED[key] = actual
    return actual


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


def _fingerprints_file():
    return config.SYNTHETIC_DIR / "fingerprints.json"


def dataset_fingerprints():
    """{entry of data/synthetic/fingerprints.json (a dataset at a length, e.g.
    "coma-F40"): the first 12 hex digits of the sha256 of the entry's canonical JSON};
    None when the file is absent."""
    path = _fingerprints_file()
    if not path.exists():
        return None
    return {
        key: hashlib.sha256(json.dumps(entry, sort_keys=True).encode()).hexdigest()[:12]
        for key, entry in json.loads(path.read_text()).items()
    }


def datasets_read(meta):
    """The entries of fingerprints.json a checkpoint read, from its metadata: those of
    the datasets its training names ("coma", "bu", "coma+bu": every "<name>-F<frames>"),
    a deformer's those of config.DEFORMATION_DATASET, all when it names none."""
    if meta.get("kind") == "deformer":
        names = config.DEFORMATION_DATASET
    else:
        names = (meta.get("training") or {}).get("dataset")
    keys = sorted(dataset_fingerprints() or {})
    if not names:
        return keys
    return [k for k in keys if any(k.startswith(f"{n}-F") for n in names.split("+"))]


def world_fingerprint(datasets=None):
    """The synthetic world this process builds: {"version": config.WORLD,
    "fingerprint": the first 12 hex digits of the sha256 of its committed dataset
    fingerprints (data/synthetic/fingerprints.json), "datasets": {entry: its digest}
    (:func:`dataset_fingerprints`) of the entries named in ``datasets`` (None: all)}.
    """
    path = _fingerprints_file()
    digest = (
        hashlib.sha256(path.read_bytes()).hexdigest()[:12] if path.exists() else None
    )
    entries = dataset_fingerprints() or {}
    return {
        "version": config.WORLD,
        "fingerprint": digest,
        "datasets": {
            k: v for k, v in entries.items() if datasets is None or k in datasets
        },
    }


def changed_datasets(recorded):
    """The entries of a recorded {dataset entry: digest} that differ in this process's
    fingerprints.json: [(entry, recorded digest, current digest or None if gone)];
    empty when the file is absent (nothing to compare with)."""
    current = dataset_fingerprints()
    if current is None:
        return []
    return [(k, d, current.get(k)) for k, d in recorded.items() if current.get(k) != d]


def check_world(meta, name):
    """A checkpoint's metadata must name the world of this process (world 1's
    checkpoints predate the record and name none) and the datasets it read as they are
    now (older records without "datasets": the whole fingerprints.json); a clear error
    naming the worlds or datasets and the retrain command if not.
    """
    recorded = meta.get("world", {"version": 1, "fingerprint": None})
    current = world_fingerprint()
    known = None not in (recorded["fingerprint"], current["fingerprint"])
    changed = changed_datasets(recorded.get("datasets", {}))
    if recorded["version"] != current["version"]:
        why = (
            f"was trained on world {recorded['version']}, but this process builds world"
            f" {current['version']}"
        )
    elif "datasets" in recorded and changed:
        why = (
            f"was trained on world {current['version']}'s datasets as they were; they"
            " have changed since: "
            + ", ".join(
                f"{k} (fingerprint {old}, now {new or 'no entry in fingerprints.json'})"
                for k, old, new in changed
            )
        )
    elif (
        "datasets" not in recorded
        and known
        and recorded["fingerprint"] != current["fingerprint"]
    ):
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
    """Write ``name``.pt (state_dict) and ``name``.json (kind, config, sha256, world:
    with the fingerprints of the datasets it read (:func:`datasets_read`), metadata)."""
    pt, js = checkpoint_paths(name)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    atomic_write(pt, lambda f: torch.save(state, f))
    read = datasets_read({"kind": kind, **metadata})
    meta = {
        "kind": kind,
        "config": model_config,
        "sha256": _sha256(pt),
        "world": world_fingerprint(read),
        **metadata,
    }
    atomic_write_text(js, json.dumps(meta, indent=1) + "\n")
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
    actual = _checked_sha256(pt, meta.get("sha256"))
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

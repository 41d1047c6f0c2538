"""Stored full-scale results: ``results/NAME.json``, a table and its provenance.

A chapter runs a small live version of an experiment within its time budget; the
full-scale one is a command (a script in benchmarks/ with ``--save NAME``; the chapter
names it) that stores its table here together with what is needed to trust and to re-run
it: the exact command, the facelib commit, the sha256 of every checkpoint it used, the
seeds, n, steps, the wall time and the number of cores.

A stored result is *stale* when a checkpoint it names no longer has the sha256 it
recorded (the model was retrained after the experiment ran), when it was made on another
world or on datasets that have changed since (the entries of
data/synthetic/fingerprints.json it records; a dataset added since changes nothing), or
when a default of the settings it records (the settings dataclasses a benchmark names as
measured: a task's, a training recipe's, registration's) has changed since (e.g.
``tasks.Fill.steps``): :func:`problems` says so, naming the file and what changed, and
a test fails on every stale or malformed file.
Files are written to a temporary file and renamed, so an interrupted command leaves the
previous result intact. A result is not saved from a tree whose facelib/ or benchmarks/
have uncommitted changes (its commit would not name the code that made it), unless the
command's ``--allow-dirty`` says so, which the result then records. Rows merged from
several runs (:func:`merged_rows`) each keep the provenance of the run that made them
(``row_provenance``).
"""

from __future__ import annotations

import datetime
import json
import os
import subprocess
import sys
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path

import torch

from . import config, registration, tables, tasks, training
from .checkpoints import changed_datasets, checkpoint_paths, world_fingerprint
from .files import atomic_write_text

RESULTS_DIR = config.RESULTS_DIR
# the settings a result may record, {class name: (its spelling, the class)}: every
# task's (tasks/settings.py), every training recipe's (training/settings.py) and
# registration's
SETTINGS_CLASSES = {
    cls.__name__: (f"{home}.{cls.__name__}", cls)
    for home, module in (("tasks", tasks.settings), ("training", training.settings))
    for cls in vars(module).values()
    if isinstance(cls, type) and is_dataclass(cls) and cls.__module__ == module.__name__
} | {"Registration": ("registration.Registration", registration.Registration)}
SCHEMA = 1
# Every stored result has these keys (and nothing is optional): the table and its
# provenance.
FIELDS = {
    "schema": int,
    "name": str,
    "title": str,
    "command": str,
    "commit": str,
    "date": str,
    "checkpoints": dict,
    "seeds": list,
    "n": int,
    "steps": list,
    "wall_time_s": float,
    "cores": int,
    "torch_threads": int,
    "columns": list,
    "rows": list,
    "notes": str,
}
# Recorded by every result saved since issue 42 (older files lack them and are not
# checked for them).
OPTIONAL = {"world": dict, "settings": dict, "row_provenance": list}
WATCHED = ("facelib", "benchmarks")  # the code a result's commit must name


def result_path(name):
    """results/NAME.json; a name is letters, digits and underscores."""
    if not name or not name.replace("_", "").isalnum():
        raise ValueError(
            f"a result name is letters, digits and underscores, got {name!r}"
        )
    return RESULTS_DIR / f"{name}.json"


def _git(*args):
    return subprocess.run(
        ["git", *args],
        cwd=config.PROJECT_ROOT,
        capture_output=True,
        text=True,
        timeout=30,
    ).stdout.strip()


def uncommitted_code():
    """The files of facelib/ and benchmarks/ with uncommitted changes (``git status
    --porcelain`` lines)."""
    try:
        return [
            line
            for line in _git("status", "--porcelain", "--", *WATCHED).splitlines()
            if line.strip()
        ]
    except (OSError, subprocess.SubprocessError):
        return []


def facelib_commit():
    """The git commit of the working tree (with '+dirty' when facelib/ or benchmarks/
    have uncommitted changes)."""
    try:
        commit = _git("rev-parse", "HEAD") or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("+dirty" if uncommitted_code() else "")


def check_clean(name, allow_dirty=False):
    """Refuse (ValueError) to store results/NAME.json from a tree with uncommitted
    changes to facelib/ or benchmarks/, unless ``allow_dirty`` (a command's
    --allow-dirty)."""
    changed = uncommitted_code()
    if changed and not allow_dirty:
        raise ValueError(
            f"results/{name}.json not written: {', '.join(WATCHED)} have uncommitted"
            f" changes ({'; '.join(changed[:5])}{' ...' if len(changed) > 5 else ''}),"
            " so the commit it would record does not name the code that made it;"
            " commit them and re-run, or pass --allow-dirty (recorded in the result)"
        )


def check_save_args(args):
    """Right after a benchmark parses its arguments: refuse ``--save`` from uncommitted
    code before any compute."""
    if getattr(args, "save", None):
        result_path(args.save)
        check_clean(args.save, args.allow_dirty)


def add_save_options(parser):
    """--save NAME and --allow-dirty for a benchmark that stores its table in
    results/NAME.json."""
    parser.add_argument(
        "--save",
        metavar="NAME",
        default=None,
        help=(
            "store the table in results/NAME.json "
            "(refused from a tree with uncommitted changes to facelib/ or benchmarks/)"
        ),
    )
    parser.add_argument(
        "--allow-dirty",
        action="store_true",
        help="with --save: store it even so (recorded)",
    )


def invoking_command():
    """The command line that is running, as a reader would type it from the repository
    root."""
    script = Path(sys.argv[0])
    if script.name == "__main__.py":
        head = f"python -m {script.parent.name}"
    else:
        try:
            head = f"python {script.resolve().relative_to(config.PROJECT_ROOT)}"
        except ValueError:
            head = f"python {script}"
    return " ".join([head, *sys.argv[1:]])


def checkpoint_sha256(name):
    """The sha256 recorded in a shipped checkpoint's JSON (what
    :func:`checkpoints.load_checkpoint` checks)."""
    _, js = checkpoint_paths(name)
    if not js.exists():
        raise FileNotFoundError(f"checkpoint {name!r} not found in {js.parent}")
    return json.loads(js.read_text())["sha256"]


@dataclass(frozen=True)
class Run:
    """How a stored result was measured: the shipped checkpoints it used (their sha256
    are read from data/checkpoints), the seeds, the sequences per row, the reverse
    steps, its wall time, and the command that rewrites it (None: the command line of
    this process), whether it may be stored from a tree with uncommitted code, and the
    settings (config dataclass instances) whose values it measured.
    """

    checkpoints: list
    seeds: list
    n: int
    steps: list
    wall_time_s: float
    command: str | None = None
    allow_dirty: bool = False  # the command's --allow-dirty
    # the config dataclasses whose defaults the result measured (staleness compares
    # them)
    settings: tuple = ()


def save_result(name, title, columns, rows, run, notes="", row_provenance=None):
    """Write results/NAME.json (the table and its :class:`Run`) atomically; returns its
    path.

    ``columns`` names the entries of every row (a row is a list, one entry per column: a
    number, a string, or a [low, high] 95 % interval).  ``row_provenance`` (from
    :func:`merged_rows`): per row, the provenance of the run that made it (None: this
    run)."""
    path = result_path(name)
    check_clean(name, run.allow_dirty)
    bad = [r for r in rows if len(r) != len(columns)]
    if bad:
        raise ValueError(
            f"every row needs {len(columns)} entries ({columns}), got {bad[0]}"
        )
    commit = facelib_commit()
    record = {
        "schema": SCHEMA,
        "name": name,
        "title": title,
        "command": run.command or invoking_command(),
        "commit": (
            commit
            + (" (stored with --allow-dirty)" if commit.endswith("+dirty") else "")
        ),
        "date": (
            datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        ),
        "checkpoints": {c: checkpoint_sha256(c) for c in sorted(run.checkpoints)},
        "seeds": [int(s) for s in run.seeds],
        "n": int(run.n),
        "steps": [int(s) for s in run.steps],
        "wall_time_s": round(float(run.wall_time_s), 1),
        "cores": os.cpu_count() or 0,
        "torch_threads": torch.get_num_threads(),
        "columns": list(columns),
        "rows": _plain(rows),
        "notes": notes,
        "world": world_fingerprint(),
        "settings": {type(s).__name__: _plain(asdict(s)) for s in run.settings},
    }
    if row_provenance is not None:
        own = {k: record[k] for k in ("commit", "date", "command")}
        record["row_provenance"] = [own if p is None else p for p in row_provenance]
    return atomic_write_text(path, json.dumps(record, indent=1) + "\n")


def merged_rows(name, rows, key_length=1):
    """``rows`` merged into the stored results/NAME.json (when it exists): a stored row
    is replaced by the new row with the same key (its first ``key_length`` entries),
    stored rows no new row replaces are kept in their order, and new rows with a new key
    follow.  For benchmarks that re-run some of a table's rows.

    Returns (rows, row_provenance) for :func:`save_result`: per row None (made by this
    run) or the commit, date and command of the run that made the stored row."""
    path = result_path(name)
    if not path.exists():
        return list(rows), [None] * len(rows)
    new = {tuple(r[:key_length]): r for r in _plain(rows)}
    stored = json.loads(path.read_text())
    own = {k: stored[k] for k in ("commit", "date", "command")}
    provenance = stored.get("row_provenance") or [own] * len(stored["rows"])
    if len(provenance) != len(stored["rows"]):
        raise ValueError(
            f"{path}: {len(provenance)} row provenances for {len(stored['rows'])} rows;"
            f" re-run the whole table: {stored['command']}"
        )
    merged, origin = [], []
    for row, made_by in zip(stored["rows"], provenance):
        key = tuple(row[:key_length])
        merged.append(new.pop(key, row))
        origin.append(None if merged[-1] is not row else made_by)
    return merged + list(new.values()), origin + [None] * len(new)


def problems(record, path="result"):
    """What is wrong with a stored result: missing or mistyped fields, another schema,
    rows that do not fit the columns, another world or changed datasets
    (:func:`world_changes`), changed settings, or checkpoints whose sha256 changed since
    it ran.  Empty when it is sound.
    """
    found = []
    for key, kind in FIELDS.items():
        if key not in record:
            found.append(f"{path}: missing field {key!r}")
        elif not isinstance(record[key], kind) and not (
            kind is float and isinstance(record[key], int)
        ):
            found.append(
                f"{path}: field {key!r} should be {kind.__name__}, is"
                f" {type(record[key]).__name__}"
            )
    if found:
        return found
    if record["schema"] != SCHEMA:
        found.append(
            f"{path}: schema {record['schema']}, this facelib reads schema {SCHEMA}"
        )
    found += [
        f"{path}: row {i} has {len(r)} entries for {len(record['columns'])} columns"
        for i, r in enumerate(record["rows"])
        if len(r) != len(record["columns"])
    ]
    for key, kind in OPTIONAL.items():
        if key in record and not isinstance(record[key], kind):
            found.append(
                f"{path}: field {key!r} should be {kind.__name__}, is"
                f" {type(record[key]).__name__}"
            )
    if "row_provenance" in record and len(record["row_provenance"]) != len(
        record["rows"]
    ):
        found.append(
            f"{path}: {len(record['row_provenance'])} row provenances for"
            f" {len(record['rows'])} rows"
        )
    if isinstance(record.get("world"), dict):
        found += [
            f"{path}: stale, {change}; re-run: {record['command']}"
            for change in world_changes(record["world"])
        ]
    if isinstance(record.get("settings", {}), dict):
        found += [
            f"{path}: stale, {change}; re-run: {record['command']}"
            for change in settings_changes(record.get("settings", {}))
        ]
    for name, stored in record["checkpoints"].items():
        try:
            shipped = checkpoint_sha256(name)
        except FileNotFoundError:
            found.append(f"{path}: checkpoint {name!r} is no longer shipped")
            continue
        if shipped != stored:
            found.append(
                f"{path}: stale, checkpoint {name!r} has sha256 {shipped[:12]}..., the"
                f" result was computed with {stored[:12]}...; re-run:"
                f" {record['command']}"
            )
    return found


def world_changes(recorded):
    """What changed in the world a result recorded: its version, or the fingerprints of
    the datasets it recorded ("datasets"; a dataset added since changes nothing), or,
    in a record without them (older results), the whole fingerprints.json."""
    current = world_fingerprint()
    now = {k: current[k] for k in ("version", "fingerprint")}
    then = {k: recorded.get(k) for k in now}
    if "datasets" not in recorded or then["version"] != now["version"]:
        if then == now:
            return []
        return [f"made on the datasets of world {then}, this process builds {now}"]
    return [
        f"made on world {current['version']}'s dataset {k} at fingerprint {old}, which"
        f" is {new or 'no entry in fingerprints.json'} now"
        for k, old, new in changed_datasets(recorded["datasets"])
    ]


def settings_changes(recorded):
    """What changed in the defaults of the settings dataclasses a result recorded
    ({class name: fields}; SETTINGS_CLASSES), e.g. "tasks.Fill.steps was 100, is 50
    now"; a class or field that no longer exists is a change too.
    """
    changes = []
    for name, values in recorded.items():
        if name not in SETTINGS_CLASSES:
            changes.append(f"the settings {name} no longer exist")
            continue
        spelling, cls = SETTINGS_CLASSES[name]
        now = _plain(asdict(cls()))
        changes += [
            (
                f"{spelling}.{k} was {v!r}, is {now[k]!r} now"
                if k in now
                else f"{spelling}.{k} is gone"
            )
            for k, v in values.items()
            if now.get(k, object()) != v
        ]
    return changes


def load_result(name):
    """Read results/NAME.json; ValueError naming the file and what changed if it is
    stale or malformed."""
    path = result_path(name)
    if not path.exists():
        raise FileNotFoundError(
            f"{path} not found; write it with the benchmark that stores it "
            f"(benchmarks/*.py --save {name}; the chapter names the command)"
        )
    record = json.loads(path.read_text())
    found = problems(record, path.name)
    if found:
        raise ValueError("; ".join(found))
    return record


def stored_results():
    """Names of the results in results/."""
    return sorted(p.stem for p in RESULTS_DIR.glob("*.json"))


def row_dicts(record):
    """The rows of a stored result as dicts keyed by its column names."""
    return [dict(zip(record["columns"], row)) for row in record["rows"]]


def stored_row(record, key):
    """The row of a stored result whose first cells are ``key`` (a tuple), e.g. ("label
    control (Alg. 1)", "ddpm", 200); an error that lists the rows' first cells when no
    row starts so."""
    if isinstance(key, str):
        raise TypeError(
            f"a row key is a tuple of the row's first cells, like ({key!r},), got the"
            f" string {key!r}"
        )
    key = tuple(key)
    for row in record["rows"]:
        if tuple(row[: len(key)]) == key:
            return row
    starts = [tuple(row[: len(key)]) for row in record["rows"]]
    raise KeyError(
        f"results/{record['name']}: no row starts with {key}; the rows start with"
        f" {starts}"
    )


def stored_value(record, key, column, interval=False):
    """The cell of ``column`` in the row ``key`` (:func:`stored_row`); ``interval``: the
    95 % interval stored in the column after it instead."""
    if column not in record["columns"]:
        raise KeyError(
            f"results/{record['name']} has no column {column!r}; columns:"
            f" {record['columns']}"
        )
    row, i = stored_row(record, key), record["columns"].index(column)
    if interval and not (i + 1 < len(row) and _is_interval(row[i + 1])):
        raise ValueError(
            f"results/{record['name']}: the column after {column!r} holds no 95 %"
            f" interval in row {key}"
        )
    return row[i + bool(interval)]


def stored_cell(record, key, column, digits=0):
    """'value [low, high]': the cell of ``column`` in the row ``key`` with its stored 95
    % interval."""
    return tables.interval_cell(
        stored_value(record, key, column),
        stored_value(record, key, column, True),
        digits,
    )


# Code changes that move the numbers of results stored before them without changing a
# checkpoint: the time of the change's commit (as results record their date), what
# changed and the results it touches.  `python -m facelib results` names them; they are
# re-run once, after the retrained denoisers (issue 43), and the chapters' live numbers
# already use the new code.
CODE_CHANGES = [
    (
        "2026-12-05 03:22 UTC",
        (
            "one random stream per chain (issue 42: the first reverse step re-added"
            " x_T's noise)"
        ),
        (
            "fill_defaults",
            "filling_table3",
            "geometry_table4",
            "geometry_lr",
            "fine_control_au",
            "fine_control_keyframes",
            "animate_magnitudes",
            "text_table2_raw",
            "text_table2_enriched",
        ),
    ),
    (
        "2026-12-07 01:51 UTC",
        (
            "options that combine (issue 57): DDIM guidance continuous in eta, one"
            " clean estimate (the flow's AU and text scores), the handshake's anchors"
            " imposed after the shared frames are averaged"
        ),
        ("long_sequences", "long_sequences_free", "few_steps", "few_steps_tasks"),
    ),
    (
        "2026-12-07 08:40 UTC",
        (
            "a DDIM chain's known frames take its own step with the model's noise"
            " estimate (issue 57: inpainting.KnownFrames.known_step)"
        ),
        ("few_steps_tasks",),
    ),
]


def code_changes_since(record):
    """The entries of :data:`CODE_CHANGES` made after ``record`` was stored that touch
    it."""
    return [
        what
        for date, what, names in CODE_CHANGES
        if record.get("name") in names and str(record.get("date", "")) < date
    ]


def catalogue():
    """One line per stored result: its name, wall time, cores and torch threads, date,
    problems (empty when sound and fresh), the code changes since it was stored that
    touch it (:data:`CODE_CHANGES`), what it does not record (older results: world,
    settings) and the command that rewrites it.
    """
    lines = []
    for name in stored_results():
        record = json.loads(result_path(name).read_text())
        found = problems(record, f"{name}.json")
        lines.append(
            dict(
                name=name,
                minutes=record.get("wall_time_s", float("nan")) / 60,
                cores=record.get("cores"),
                threads=record.get("torch_threads"),
                date=record.get("date"),
                problems=found,
                command=record.get("command"),
                changes=code_changes_since(record),
                unrecorded=[k for k in ("world", "settings") if k not in record],
            )
        )
    return lines


def _plain(value):
    """JSON-ready copy: numpy scalars and arrays become Python numbers and lists; floats
    keep 6 significant digits (a setting of 1e-05 stays 1e-05, a rate of 85.2071 % stays
    85.2071)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    if isinstance(value, float):
        return float(f"{value:.6g}")
    return value


def markdown_table(record, fmt="{:.2f}", columns=None):
    """A stored result as a Markdown table under a line saying it is stored: its command
    and date.

    Numbers are formatted with ``fmt`` (those below 0.1 with two significant digits).  A
    column of 95 % intervals ([low, high] entries) is merged into the column before it,
    "value [low, high]", so that wide tables fit the page.  ``columns``: only these of
    the record's columns, in this order (None: all).
    """
    if columns is not None:
        unknown = [c for c in columns if c not in record["columns"]]
        if unknown:
            raise ValueError(
                f"{record['name']} has no column {unknown[0]!r}; its columns:"
                f" {record['columns']}"
            )
        keep = [record["columns"].index(c) for c in columns]
        for k, (c, i) in enumerate(zip(columns, keep)):
            values = [row[i] for row in record["rows"]]
            if any(_is_interval(v) for v in values) and (
                k == 0 or keep[k - 1] != i - 1
            ):
                raise ValueError(
                    f"the interval column {c!r} must follow its value column"
                    f" {record['columns'][i - 1]!r}, as in {record['name']}"
                )
        record = dict(
            record,
            columns=list(columns),
            rows=[[row[k] for k in keep] for row in record["rows"]],
        )

    def cell(v):
        if _is_interval(v):
            return f"[{fmt.format(v[0])}, {fmt.format(v[1])}]"
        if isinstance(v, float):
            # small settings: 0.0003, not 0.00
            return f"{v:.2g}" if 0 < abs(v) < 0.1 else fmt.format(v)
        return "—" if v is None else str(v)  # a measure the row has not

    columns, rows = list(record["columns"]), [
        [cell(v) for v in row] for row in record["rows"]
    ]
    for i in range(len(columns) - 1, 0, -1):
        values = [row[i] for row in record["rows"]]
        if any(_is_interval(v) for v in values) and all(
            _is_interval(v) or v in ("", None) for v in values
        ):
            columns[i - 1] = f"{columns[i - 1]} [95 % interval]"
            del columns[i]
            for row in rows:
                row[i - 1] = f"{row[i - 1]} {row.pop(i)}".strip()
    path = result_path(record["name"])  # results/NAME.json
    path = (
        path.relative_to(config.PROJECT_ROOT)
        if path.is_relative_to(config.PROJECT_ROOT)
        else path
    )
    head = (
        f"*Stored result* `{path}`: {record['title']} (n = {record['n']},"
        f" {record['wall_time_s'] / 60:.0f} min on {record['cores']} cores with"
        f" {record['torch_threads']} torch thread(s), {record['date']}; re-run:"
        f" `{record['command']}`)\n\n"
    )
    return head + tables.markdown(columns, rows)


def _is_interval(v):
    return (
        isinstance(v, (list, tuple))
        and len(v) == 2
        and all(isinstance(u, (int, float)) for u in v)
    )


def store_training_times():
    """results/train_all.json: every shipped checkpoint of this world with its steps and
    the wall time its checkpoint recorded (the last run's, when a stopped run was
    resumed); ``python -m facelib train all`` writes it after training."""
    rows, seeds = [], set()
    for name, (model, _) in training.SHIPPED.items():
        if training.trained_on_this_world(name):
            meta = json.loads(checkpoint_paths(name)[1].read_text())
            steps = meta["training"].get("epochs") or meta["training"]["steps"]
            seeds.add(int(meta["training"].get("seed", 0)))
            rows.append(
                [
                    name,
                    model,
                    steps,
                    meta.get("wall_time_s"),
                    bool(meta.get("resumed", False)),
                ]
            )
    save_result(
        "train_all",
        "Training every shipped checkpoint (python -m facelib train all)",
        ["checkpoint", "model", "steps (epochs for the IC)", "seconds", "resumed"],
        rows,
        Run(
            checkpoints=[r[0] for r in rows],
            seeds=sorted(seeds),
            n=len(rows),
            steps=[],
            wall_time_s=sum(r[3] or 0.0 for r in rows),
            command="python -m facelib train all",
        ),
        notes=(
            "seconds: the wall time recorded in each checkpoint (None: trained before"
            " it was recorded)"
        ),
    )

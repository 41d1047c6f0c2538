"""Run one chapter of the book, as an instructor would in class (``make chapter N=05``).

The chapter executes with the book's directory as working directory, in book mode or,
with ``fast``, in fast mode (``FACELIB_FAST=1``); the executed notebook (with its
outputs) is written to ``_build/chapters/`` so that the committed one stays without
outputs.  The wall time is printed, compared with the book's budget (:data:`BUDGET_S`)
and recorded in ``book/run_times.json``, from which each chapter's header reads its run
time (:func:`run_time_text`).
"""

from __future__ import annotations

import datetime
import json
import os
import time

from . import config

BOOK_DIR = config.PROJECT_ROOT / "book"
OUT_DIR = config.PROJECT_ROOT / "_build" / "chapters"
# The budget of issue 23: every chapter executes within this many seconds on an idle
# 2-core machine.
BUDGET_S = {"book": 300, "fast": 60}
TIMES_PATH = BOOK_DIR / "run_times.json"


def chapters():
    """The chapter notebooks, in book order, then the appendices: {'01':
    Path('book/01_face_world.ipynb'), ..., 'a1': Path('book/a1_...ipynb')}."""
    found = sorted(BOOK_DIR.glob("[0-9][0-9]_*.ipynb")) + sorted(
        BOOK_DIR.glob("a[0-9]_*.ipynb")
    )
    return {p.name[:2]: p for p in found}


def record_time(path, mode, seconds, load=0.0):
    """Store a chapter's wall time in ``mode`` ("book" or "fast") in
    book/run_times.json, with the date, the machine's cores and the load average (other
    jobs) when it started."""
    times = json.loads(TIMES_PATH.read_text()) if TIMES_PATH.exists() else {}
    times.setdefault(path.stem, {})[mode] = {
        "seconds": round(seconds, 1),
        "cores": os.cpu_count(),
        "load": round(load, 1),
        "date": datetime.date.today().isoformat(),
    }
    TIMES_PATH.write_text(json.dumps(times, indent=1, sort_keys=True) + "\n")


def run_time_text(stem, mode):
    """A chapter's recorded wall time in ``mode``, for its header: '3.1 min (2 cores,
    2026-12-03)'."""
    if mode not in BUDGET_S:
        raise ValueError(f"mode must be one of {tuple(BUDGET_S)}, got {mode!r}")
    record = (
        (json.loads(TIMES_PATH.read_text()) if TIMES_PATH.exists() else {})
        .get(stem, {})
        .get(mode)
    )
    if record is None:
        return "not measured yet (`make chapter`)"
    s = record["seconds"]
    value = f"{s / 60:.1f} min" if s >= 90 else f"{s:.0f} s"
    busy = ", shared with other jobs" if record.get("load", 0) >= 1 else ""
    return f"{value} ({record['cores']} cores{busy}, {record['date']})"


def find_chapter(name):
    """A chapter by number ('5', '05'), by stem ('05_label_control') or by title part
    ('label_control')."""
    known = chapters()
    key = str(name).strip().removesuffix(".ipynb")
    if key.isdigit() and f"{int(key):02d}" in known:
        return known[f"{int(key):02d}"]
    if key.lower() in known:  # an appendix: a1
        return known[key.lower()]
    for path in known.values():
        if key and key in (path.stem, path.stem[3:]):
            return path
    listing = "\n".join(f"  {k}  {p.stem}" for k, p in known.items())
    raise ValueError(
        f"no chapter {name!r}; the chapters are (use the number, e.g. N=05):\n{listing}"
    )


def run_chapter(name, fast=False, timeout=3600):
    """Execute a chapter; returns (seconds, path of the executed notebook).  Raises on a
    failing cell."""
    import nbformat
    from nbclient import NotebookClient

    path = find_chapter(name)
    if fast:
        os.environ["FACELIB_FAST"] = "1"
    else:
        os.environ.pop("FACELIB_FAST", None)
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(
        notebook,
        timeout=timeout,
        kernel_name="python3",
        resources={"metadata": {"path": str(BOOK_DIR)}},
    )
    load, t0 = os.getloadavg()[0], time.perf_counter()
    try:
        client.execute()
    finally:
        seconds = time.perf_counter() - t0
        OUT_DIR.mkdir(parents=True, exist_ok=True)
        out = OUT_DIR / path.name
        nbformat.write(notebook, out)
    record_time(path, "fast" if fast else "book", seconds, load)
    return seconds, out

"""Run one chapter of the book, as an instructor would in class (``make chapter N=05``).

The chapter executes with the book's directory as working directory, in book mode or, with
``fast``, in fast mode (``FACELIB_FAST=1``); the executed notebook (with its outputs) is written to
``_build/chapters/`` so that the committed one stays without outputs.  The wall time is printed
and compared with the book's budget (:data:`BUDGET_S`).
"""
from __future__ import annotations

import os
import time

from . import config

BOOK_DIR = config.PROJECT_ROOT / "book"
OUT_DIR = config.PROJECT_ROOT / "_build" / "chapters"
# The budget of issue 23: every chapter executes within this many seconds on an idle 2-core machine.
BUDGET_S = {"book": 300, "fast": 60}


def chapters():
    """The chapter notebooks, in book order: {'01': Path('book/01_face_world.ipynb'), ...}."""
    return {p.name[:2]: p for p in sorted(BOOK_DIR.glob("[0-9][0-9]_*.ipynb"))}


def find_chapter(name):
    """A chapter by number ('5', '05'), by stem ('05_label_control') or by title part ('label_control')."""
    known = chapters()
    key = str(name).strip().removesuffix(".ipynb")
    if key.isdigit() and f"{int(key):02d}" in known:
        return known[f"{int(key):02d}"]
    for path in known.values():
        if key and key in (path.stem, path.stem[3:]):
            return path
    listing = "\n".join(f"  {k}  {p.stem}" for k, p in known.items())
    raise ValueError(f"no chapter {name!r}; the chapters are (use the number, e.g. N=05):\n{listing}")


def run_chapter(name, fast=False, timeout=3600):
    """Execute a chapter; returns (seconds, path of the executed notebook).  Raises on a failing cell."""
    import nbformat
    from nbclient import NotebookClient

    path = find_chapter(name)
    if fast:
        os.environ["FACELIB_FAST"] = "1"
    else:
        os.environ.pop("FACELIB_FAST", None)
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(BOOK_DIR)}})
    t0 = time.perf_counter()
    try:
        client.execute()
    finally:
        seconds = time.perf_counter() - t0
        OUT_DIR.mkdir(parents=True, exist_ok=True)
        out = OUT_DIR / path.name
        nbformat.write(notebook, out)
    return seconds, out

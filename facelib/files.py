"""Writing a file all or nothing: the one atomic write of the package.

Every file that another process may read while it is written (a dataset cache, a
sentence embedding, a stored result, a training state, a checkpoint) is written here: a
kill mid-write leaves the previous file (or none), and two processes writing the same
file at once leave one whole copy, never a mix.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def atomic_write(path, write, mode="wb"):
    """Write ``path`` by ``write(f)`` into a temporary file beside it (opened with
    ``mode``: "wb" or "w"), flushed to the disk and then renamed over ``path`` (a rename
    within a folder is atomic).  The temporary file is removed whatever happens.
    Returns ``path``."""
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def atomic_write_text(path, text):
    """``path`` holding ``text``, written all or nothing (:func:`atomic_write`)."""
    return atomic_write(path, lambda f: f.write(text), mode="w")

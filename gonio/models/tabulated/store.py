"""Where tables live: shipped package data, a user cache, loading and saving.

A table is a compressed ``.npz`` file holding float32 arrays and the constants of the
coordinate maps it was built with.  :func:`load` looks for ``<name>.npz`` first in the
user cache directory (``$GONIO_TABLE_DIR``, default ``~/.cache/gonio/tables``), where
``gonio tables build`` writes, then in the package's ``data/`` directory, where the
tables gonio ships live.  Loading is lazy (first use of a tabulated model) and cached per
process.
"""
from __future__ import annotations

import math
import os
from functools import lru_cache
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["PACKAGE_DIR", "cache_dir", "find", "load", "save", "clear_cache", "check_constants", "TableError"]

#: Directory of the tables shipped with gonio.
PACKAGE_DIR = Path(__file__).resolve().parent / "data"


class TableError(ValueError):
    """A table is missing or was built with other coordinate constants."""


def check_constants(arrays: Mapping[str, np.ndarray], expected: Mapping[str, float], name: str) -> None:
    """Raise :class:`TableError` unless the table was built with the ``expected`` constants."""
    for key, value in expected.items():
        found = float(arrays.get(key, np.nan))
        if not math.isclose(found, value, rel_tol=1e-12):
            raise TableError(
                f"table {str(arrays.get('path', name))} was built with {key} = {found:g}, this gonio "
                f"reads {key} = {value:g}; rebuild it with 'gonio tables build {name}'"
            )


def cache_dir() -> Path:
    """The user table directory: ``$GONIO_TABLE_DIR`` or ``~/.cache/gonio/tables``."""
    configured = os.environ.get("GONIO_TABLE_DIR")
    return Path(configured).expanduser() if configured else Path.home() / ".cache" / "gonio" / "tables"


def find(name: str) -> Path | None:
    """Path of table ``name`` (user cache first, then shipped), or None."""
    for directory in (cache_dir(), PACKAGE_DIR):
        path = directory / f"{name}.npz"
        if path.is_file():
            return path
    return None


def save(path: Path, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write ``arrays`` to ``path`` (compressed; float64 tables (3-D and up) as float32)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stored = {
        key: (value.astype(np.float32) if value.dtype == np.float64 and value.ndim >= 3 else value)
        for key, value in ((k, np.asarray(v)) for k, v in arrays.items())
    }
    temporary = path.with_suffix(".tmp.npz")
    np.savez_compressed(temporary, **stored)
    os.replace(temporary, path)
    load.cache_clear()
    return path


@lru_cache(maxsize=8)
def load(name: str, path: Path | None = None) -> dict[str, np.ndarray]:
    """Load table ``name`` (from ``path`` if given) as float64 arrays.

    Raises
    ------
    TableError
        If no table is found (the message says how to build one).
    """
    path = find(name) if path is None else Path(path)
    if path is None or not path.is_file():
        raise TableError(
            f"no table {name!r} in {cache_dir()} or {PACKAGE_DIR}; build it with "
            f"'gonio tables build {name}'"
        )
    with np.load(path) as data:
        arrays = {key: np.asarray(data[key], dtype=np.float64) for key in data.files}
    arrays["path"] = np.asarray(str(path))
    return arrays


def clear_cache() -> list[Path]:
    """Delete every table in the user cache directory; returns the deleted paths."""
    directory = cache_dir()
    removed = sorted(directory.glob("*.npz")) if directory.is_dir() else []
    for path in removed:
        path.unlink()
    load.cache_clear()
    return removed

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
import re
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["PACKAGE_DIR", "cache_dir", "find", "load", "save", "clear_cache", "cache_contents", "is_built_table",
           "written_by_builder", "table_file_names", "check_constants", "TableError", "SIGNATURE_KEY",
           "RENDERED_NAME"]

#: Directory of the tables shipped with gonio.
PACKAGE_DIR = Path(__file__).resolve().parent / "data"
#: Array every table written by :func:`save` holds (value: :data:`SIGNATURE_VERSION`).
SIGNATURE_KEY = "gonio_table_format"
SIGNATURE_VERSION = 1
#: Arrays every table built before the signature holds (what ``describe`` reads).
LEGACY_KEYS = frozenset({"shape", "rtol", "build_seconds"})
#: Names of the tables of rendered surfaces (:mod:`gonio.surfaces.table`): one per
#: sample, named by its kind and the start of the SHA-256 of its cache key.
RENDERED_NAME = re.compile(r"surface-[a-z]+-[0-9a-f]{16}\.npz")


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
    """Write ``arrays`` to ``path`` (compressed; float64 tables (3-D and up) as float32).

    The file also holds :data:`SIGNATURE_KEY`, by which :func:`clear_cache` recognises the
    tables gonio wrote.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stored = {
        key: (value.astype(np.float32) if value.dtype == np.float64 and value.ndim >= 3 else value)
        for key, value in ((k, np.asarray(v)) for k, v in arrays.items())
    }
    stored[SIGNATURE_KEY] = np.array(SIGNATURE_VERSION)
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


def table_file_names() -> tuple[str, ...]:
    """The file names of the tables gonio builds (``<name>.npz`` for every known table)."""
    from . import TABLES

    return tuple(f"{name}.npz" for name in sorted(TABLES))


def written_by_builder(path: Path) -> bool:
    """Whether the file at ``path`` is a table written by gonio's builder (any name).

    It must be a readable ``.npz`` holding :data:`SIGNATURE_KEY` (tables written by
    :func:`save`) or, for tables written before the signature existed, every array the
    builder writes for any table (:data:`LEGACY_KEYS`).
    """
    if path.is_symlink() or not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            keys = set(data.files)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return False
    return SIGNATURE_KEY in keys or LEGACY_KEYS <= keys


def is_built_table(path: Path) -> bool:
    """Whether ``path`` is a table of the user cache that gonio built: its name is one of
    :func:`table_file_names` or of a rendered surface (:data:`RENDERED_NAME`), and
    :func:`written_by_builder` recognises its content."""
    named = path.name in table_file_names() or RENDERED_NAME.fullmatch(path.name) is not None
    return named and written_by_builder(path)


def cache_contents() -> tuple[list[Path], list[Path]]:
    """The user table directory split into (tables gonio built, every other entry)."""
    directory = cache_dir()
    if not directory.is_dir():
        return [], []
    entries = sorted(directory.iterdir())
    tables = [path for path in entries if is_built_table(path)]
    return tables, [path for path in entries if path not in tables]


def clear_cache() -> list[Path]:
    """Delete the tables gonio built from the user cache directory; returns their paths.

    Only files recognised by :func:`is_built_table` are deleted: any other file there (a
    user's own ``.npz`` included) is kept; :func:`cache_contents` lists them.
    """
    removed, _ = cache_contents()
    for path in removed:
        path.unlink()
    load.cache_clear()
    return removed

"""Safe file writes: atomic replacement with the permissions a normal write would give.

Every file gonio writes in one piece (recording metadata, fit results, reports) goes
through :func:`write_atomic`: the bytes go to a temporary file in the same folder, are
flushed to disk, get the permissions of the file they replace (or, for a new file, those
of ``open()`` under the current umask, ``0o666 & ~umask``), and then replace the target in
one ``os.replace``. A failure at any step (a full disk, a vanished folder) leaves the
previous file untouched and no temporary file behind.

A folder one process writes over time (a recording) is held with :func:`lock_folder`, so
that a second writer is refused instead of interleaving its rows.
"""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["write_atomic", "default_file_mode", "lock_folder", "unlock_folder", "FolderLock", "FolderBusy", "json_default"]


def default_file_mode() -> int:
    """Permission bits of a file created now by ``open(path, "w")``: ``0o666 & ~umask``."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically (see the module notes); return the path.

    Parameters
    ----------
    path : path
        Target file; its folder must exist.
    data : bytes or str
        Content; text is encoded as UTF-8.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> write_atomic(folder / "a.txt", "hello").read_text()
    'hello'
    """
    path = Path(path)
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        mode = stat.S_IMODE(path.stat().st_mode)
    except FileNotFoundError:
        mode = default_file_mode()
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


class FolderBusy(OSError):
    """Another process holds the folder's lock (:func:`lock_folder`)."""


class FolderLock:
    """An exclusive ``flock`` held on a folder (:func:`lock_folder`); released by
    :meth:`release`, or when the object is garbage-collected or its process ends."""

    def __init__(self, descriptor: int) -> None:
        self._descriptor: int | None = descriptor

    def release(self) -> None:
        """Release the lock (once; later calls do nothing)."""
        if self._descriptor is not None:
            descriptor, self._descriptor = self._descriptor, None
            os.close(descriptor)

    def __del__(self) -> None:
        self.release()


def lock_folder(folder: str | Path) -> FolderLock | None:
    """Hold an exclusive lock on ``folder`` while one process writes it.

    The lock is an advisory ``flock`` on the folder itself (created if missing), taken
    without waiting: a second writer is refused at once. No file is added to the folder.
    The operating system releases the lock when the holder's descriptor is closed or the
    holder ends in any way, ``kill -9`` and power loss included, so a stale lock never
    blocks a later writer. It protects against every process that takes the same lock on
    this machine (and, on NFS, on others where ``flock`` is forwarded to the server); where
    ``fcntl`` is missing (Windows) no lock is taken and None is returned.

    Parameters
    ----------
    folder : path
        The folder to write.

    Returns
    -------
    FolderLock or None
        Keep it while writing; :meth:`FolderLock.release` releases the lock.

    Raises
    ------
    FolderBusy
        Another process (or another writer of this one) holds the lock.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        return None
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(descriptor)
        raise FolderBusy(f"{folder} is being written by another writer") from None
    return FolderLock(descriptor)


def unlock_folder(lock: FolderLock | None) -> None:
    """Release a lock :func:`lock_folder` took (None: nothing to release)."""
    if lock is not None:
        lock.release()


def json_default(value: Any) -> Any:
    """``json.dumps(..., default=json_default)``: numpy numbers and arrays as JSON numbers
    and lists, anything else (a path) as its text.

    >>> import json, numpy as np
    >>> json.dumps({"n": np.int64(3), "x": np.arange(2.0), "p": Path("a/b")}, default=json_default)
    '{"n": 3, "x": [0.0, 1.0], "p": "a/b"}'
    """
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)

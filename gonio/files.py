"""Safe file writes: atomic replacement with the permissions a normal write would give.

Every file gonio writes in one piece (recording metadata, fit results, reports) goes
through :func:`write_atomic`: the bytes go to a temporary file in the same folder, are
flushed to disk, get the permissions of the file they replace (or, for a new file, those
of ``open()`` under the current umask, ``0o666 & ~umask``), and then replace the target in
one ``os.replace``. A failure at any step (a full disk, a vanished folder) leaves the
previous file untouched and no temporary file behind.
"""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

__all__ = ["write_atomic", "default_file_mode"]


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

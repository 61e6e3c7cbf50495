"""Checks of the output paths given on the command line, shared by the sub-commands."""
from __future__ import annotations

from pathlib import Path

from . import CLIError

__all__ = ["check_output_folder"]


def check_output_folder(out: str, what: str, argument: str = "--out") -> Path:
    """Refuse an output argument that cannot be a folder for ``what``; return it as a Path.

    Parameters
    ----------
    out : str
        The argument's value.
    what : str
        What the folder holds, for the message (``"recording"``, ``"report"``).
    argument : str
        The option's name, for the message.

    Raises
    ------
    CLIError
        For an empty name (it would write into the current folder), an existing file, or
        a device or other special file such as /dev/null.
    """
    if not out.strip():
        raise CLIError(f"{argument} {out!r}: expected the name of a {what} folder (an empty name would "
                       "write into the current folder)")
    path = Path(out)
    if path.exists() and not path.is_dir():
        kind = "an existing file" if path.is_file() else "a device or special file, not a folder"
        raise CLIError(f"{argument} {out}: is {kind}; expected a {what} folder (created if missing)")
    return path

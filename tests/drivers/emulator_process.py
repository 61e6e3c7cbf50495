"""Helpers for tests that run ``gonio emulator`` in another process."""
from __future__ import annotations

import subprocess
import time


def banner(process: subprocess.Popen, timeout: float = 30.0) -> list[str]:
    """The lines ``gonio emulator`` prints up to "serving ..." (its addresses), or up to the
    end of its output if it stops first, waiting at most ``timeout`` [s]."""
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        lines.append(line)
        if line.startswith("serving") or not line:
            break
    return lines

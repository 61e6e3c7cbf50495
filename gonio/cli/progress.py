"""A dependency-free progress line for long CLI work (acquisition, MCMC)."""
from __future__ import annotations

import contextlib
import logging
import sys
import time
from typing import Iterator, TextIO


def _clock(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    hours, rest = divmod(seconds, 3600)
    minutes, sec = divmod(rest, 60)
    return f"{hours:d}:{minutes:02d}:{sec:02d}"


class ProgressLine:
    """Redraws one status line on a terminal; prints a line every ``step`` fraction otherwise.

    Parameters
    ----------
    label : str
        What is progressing ("points", "steps").
    stream : file, optional
        Where to write (default standard error, so standard output stays clean).
    step : float
        When not on a terminal, print a new line every ``step`` of the total.
    """

    def __init__(self, label: str, stream: TextIO | None = None, step: float = 0.1, width: int = 28):
        self.label = label
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.step = step
        self.width = width
        self._next_fraction = 0.0
        self._last_draw = 0.0

    def update(self, done: int, total: int, eta_seconds: float | None = None, extra: str = "") -> None:
        """Show ``done`` of ``total`` with the estimated time left [s] and extra text."""
        fraction = done / total if total else 1.0
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "." * (self.width - filled)
        eta = f" ETA {_clock(eta_seconds)}" if eta_seconds is not None and done < total else ""
        text = f"[{bar}] {done}/{total} {self.label}{eta}{'  ' + extra if extra else ''}"
        if self.tty:
            now = time.monotonic()
            if done == total or now - self._last_draw > 0.1:
                self.stream.write("\r" + text[:160].ljust(100))
                self.stream.flush()
                self._last_draw = now
            if done == total:
                self.stream.write("\n")
        elif fraction >= self._next_fraction or done == total:
            self.stream.write(text + "\n")
            self.stream.flush()
            self._next_fraction = fraction + self.step


@contextlib.contextmanager
def fitting_progress(quiet: bool) -> Iterator[None]:
    """Print the fitting code's progress lines (logger ``gonio.fitting``, INFO: a slow
    least-squares fit's heartbeat) to stderr while the block runs, unless ``quiet``."""
    if quiet:
        yield
        return
    logger = logging.getLogger("gonio.fitting")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("  %(message)s"))
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)

"""Simulated time of the emulated lab.

All instruments of one rig share a :class:`SimClock`.  In *fast* mode (the default) the
clock only moves when the simulation says time passes (a move, an exposure, bytes on a
line): replies come back at once and the clock jumps.  In *real-time* mode the clock follows
the wall clock and waiting really sleeps, so the instruments answer with hardware timing.
"""
from __future__ import annotations

import math
import threading
import time

__all__ = ["SimClock", "transfer_time"]


def transfer_time(n_bytes: int, baudrate: int, bits_per_byte: int = 10) -> float:
    """Time to send ``n_bytes`` over an asynchronous serial line [s].

    Parameters
    ----------
    n_bytes : int
        Number of bytes.
    baudrate : int
        Line speed [bit/s].
    bits_per_byte : int
        Bits on the wire per byte: 8N1 framing is 1 start + 8 data + 1 stop = 10.

    Examples
    --------
    >>> round(transfer_time(192, 19200), 6)
    0.1
    """
    return n_bytes * bits_per_byte / float(baudrate)


def _finite(value: float, name: str) -> float:
    """``value`` as a float, or ValueError naming ``name`` if it is NaN or infinite."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite time [s], got {value!r}")
    return value


class SimClock:
    """A monotonic simulated clock [s], shared by the instruments of one rig.

    Parameters
    ----------
    realtime : bool
        False (fast mode): time advances only through :meth:`advance` / :meth:`wait_until`,
        which return at once.  True: time follows the wall clock and waiting sleeps.
    start : float
        Simulated time at creation [s].

    Raises
    ------
    ValueError
        For a non-finite start time, and from :meth:`wait_until` / :meth:`advance` for a
        non-finite time or duration: a clock at infinity would stop every instrument of
        the rig (each error timestamp and transfer time is computed from it), so the
        clock refuses to get there whatever its caller computed.

    Examples
    --------
    >>> clock = SimClock()
    >>> clock.wait_until(2.5); clock.now()
    2.5
    >>> clock.advance(0.5); clock.now()
    3.0
    """

    def __init__(self, realtime: bool = False, start: float = 0.0) -> None:
        self.realtime = bool(realtime)
        self._lock = threading.Lock()
        self._offset = _finite(start, "start")
        self._wall0 = time.monotonic()

    def now(self) -> float:
        """Current simulated time [s]."""
        if self.realtime:
            return self._offset + (time.monotonic() - self._wall0)
        return self._offset

    def wait_until(self, t: float) -> None:
        """Let simulated time reach ``t`` [s] (jump in fast mode, sleep in real time)."""
        t = _finite(t, "t")
        if self.realtime:
            delay = t - self.now()
            if delay > 0:
                time.sleep(delay)
            return
        with self._lock:
            if t > self._offset:
                self._offset = float(t)

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass (negative or non-finite values are an error)."""
        seconds = _finite(seconds, "seconds")
        if seconds < 0:
            raise ValueError(f"seconds must be >= 0, got {seconds!r}")
        if self.realtime:
            time.sleep(seconds)
            return
        with self._lock:
            self._offset = _finite(self._offset + seconds, "the clock after the advance")

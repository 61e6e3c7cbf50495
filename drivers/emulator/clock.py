"""Simulated time of the emulated lab.

All instruments of one rig share a :class:`SimClock`, in one of three modes
(docs/emulator.md, "Time"):

``event``
    Time moves only when the simulation says time passes (a move waited for, an
    exposure, bytes on a line): replies come back at once and the clock jumps. Runs are
    reproducible from the seed whatever the host does; a client that waits on its own
    clock (``time.sleep``) waits in a frozen lab. The default of :class:`EmulatedRig`
    and of gonio's own commands.
``wall``
    Time follows the wall clock times ``speed`` and jumps ahead whenever a client waits
    on the rig (``WS``, ``*OPC?`` after an exposure, a reply's transfer time), so a
    client that sleeps or polls sees the lamp warm and a move end as on the hardware
    (``speed`` times faster), and a client that blocks sees the event mode's speed. The
    default of ``gonio emulator``, which serves lab software. Decision: one client's
    wait moves the rig's single clock for every client (a rig cannot tell a client that
    sleeps from one that went away); the others then see the instrument run ahead of
    their wall clock, never behind it, and every device keeps one consistent time.
``realtime``
    Time follows the wall clock times ``speed`` and waiting really sleeps: hardware
    timing, replies streamed at the line's rate.
"""
from __future__ import annotations

import math
import threading
import time

__all__ = ["CLOCK_MODES", "SimClock", "transfer_time"]


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


def _speed(value: float) -> float:
    """``value`` as a finite positive speed, or ValueError."""
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"speed must be a finite number > 0 (simulated seconds per wall second), got {value!r}")
    return value


#: The clock's modes (module notes).
CLOCK_MODES = ("event", "wall", "realtime")


class SimClock:
    """A monotonic simulated clock [s], shared by the instruments of one rig.

    Parameters
    ----------
    mode : {"event", "wall", "realtime"}
        How time passes (module notes).
    speed : float
        Simulated seconds per wall-clock second in the ``wall`` and ``realtime`` modes
        (> 0; 1 = real time); ignored in ``event`` mode.
    start : float
        Simulated time at creation [s].

    Raises
    ------
    ValueError
        For an unknown mode, a speed that is not a finite positive number, a non-finite
        start time, and from :meth:`wait_until` / :meth:`advance` for a non-finite time or
        duration: a clock at infinity would stop every instrument of the rig (each error
        timestamp and transfer time is computed from it), so the clock refuses to get
        there whatever its caller computed.

    Examples
    --------
    >>> clock = SimClock()
    >>> clock.wait_until(2.5); clock.now()
    2.5
    >>> clock.advance(0.5); clock.now()
    3.0
    >>> wall = SimClock("wall", speed=1000.0)
    >>> wall.pause(); t = wall.now(); wall.advance(2.0); wall.now() == t + 2.0
    True
    """

    def __init__(self, mode: str = "event", speed: float = 1.0, start: float = 0.0) -> None:
        if mode not in CLOCK_MODES:
            raise ValueError(f"clock mode must be one of {CLOCK_MODES}, got {mode!r}")
        self.mode = mode
        self._lock = threading.Lock()
        self._speed = _speed(speed)
        self._paused = False
        # (simulated time at the anchor [s], wall time of the anchor [s], simulated s per wall s):
        # replaced whole, so a reader never sees half an update
        self._anchor = (_finite(start, "start"), time.monotonic(), self._rate())

    @property
    def realtime(self) -> bool:
        """Whether waiting sleeps and replies stream at the line's rate."""
        return self.mode == "realtime"

    @property
    def speed(self) -> float:
        """Simulated seconds per wall-clock second (``wall`` and ``realtime`` modes)."""
        return self._speed

    @property
    def paused(self) -> bool:
        """Whether the wall clock's part is stopped (:meth:`pause`)."""
        return self._paused

    def now(self) -> float:
        """Current simulated time [s]."""
        sim, wall, rate = self._anchor
        return sim + rate * (time.monotonic() - wall) if rate else sim

    def wait_until(self, t: float) -> None:
        """Let simulated time reach ``t`` [s]: a jump (``event``, ``wall``) or a sleep (``realtime``)."""
        t = _finite(t, "t")
        if self.realtime:
            delay = (t - self.now()) / self._speed
            if delay > 0:
                time.sleep(delay)
            return
        with self._lock:
            if t > self.now():
                self._anchor = (t, time.monotonic(), self._anchor[2])

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass (negative or non-finite values are an error)."""
        seconds = _finite(seconds, "seconds")
        if seconds < 0:
            raise ValueError(f"seconds must be >= 0, got {seconds!r}")
        if self.realtime:
            time.sleep(seconds / self._speed)
            return
        with self._lock:
            later = _finite(self.now() + seconds, "the clock after the advance")
            self._anchor = (later, time.monotonic(), self._anchor[2])

    def set_speed(self, speed: float) -> None:
        """Change the simulated seconds per wall second from now on (``wall``, ``realtime``)."""
        with self._lock:
            self._speed = _speed(speed)
            self._reanchor()

    def pause(self) -> None:
        """Stop the wall clock's part of the time (``wall`` mode); waits still jump it.

        Raises
        ------
        ValueError
            In ``realtime`` mode, whose waits sleep until the time comes and would never end.
        """
        if self.realtime:
            raise ValueError("a real-time clock cannot pause (its waits sleep until the time comes); "
                             "use the 'wall' mode to pause or step time")
        with self._lock:
            self._paused = True
            self._reanchor()

    def resume(self) -> None:
        """Let the wall clock's part run again after :meth:`pause`."""
        with self._lock:
            self._paused = False
            self._reanchor()

    def _rate(self) -> float:
        """Simulated seconds per wall second now: 0 in event mode or paused, else the speed."""
        return 0.0 if self.mode == "event" or self._paused else self._speed

    def _reanchor(self) -> None:
        """Start a new wall-clock anchor at the current time with the current rate (lock held)."""
        self._anchor = (self.now(), time.monotonic(), self._rate())

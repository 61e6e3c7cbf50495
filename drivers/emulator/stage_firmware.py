"""Firmware of the emulated motion controller: a Newport ESP300 dialect with three axes.

Syntax, commands, replies and error codes follow the vendor manual (Newport, "ESP300
Motion Controller/Driver User's Manual", section 3 "Remote mode", 3.4.1 command syntax,
the command descriptions including TE and TB, and Appendix A error messages); the subset
and the emulator's decisions are documented in docs/protocol.md.

Axes (degrees): 1 camera swing, 2 lamp polar angle, 3 lamp azimuth.  Moves follow
trapezoidal velocity profiles in simulated time; a move is refused when its end point is
outside the software limits or would bring camera and lamp closer than the minimum
separation (an interlock callback supplied by the rig).

Every numeric parameter has a finite range (docs/protocol.md, section 1, "Parameter
ranges"), and a number outside it is refused with the manual's code: 7 for a non-axis
parameter (the ``WS`` delay), ``x01`` for an axis parameter, ``x10``/``x11`` for a
velocity/acceleration above the axis maximum, ``x06``/``x07`` for a target beyond the
software limits.  So no line can make a move or a wait last forever: the firmware
never computes a non-finite time.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .clock import SimClock

__all__ = ["AxisConfig", "DEFAULT_AXES", "MotionProfile", "trapezoid_profile", "move_duration", "Esp300Firmware",
           "GENERAL_ERRORS", "AXIS_ERRORS", "MAX_WS_DELAY_MS", "RATE_REFERENCE_TIME_S"]

#: General (non-axis) error messages, ESP300 manual Appendix A.
GENERAL_ERRORS = {
    0: "NO ERROR DETECTED",
    6: "COMMAND DOES NOT EXIST",
    7: "PARAMETER OUT OF RANGE",
    9: "AXIS NUMBER OUT OF RANGE",
    27: "COMMAND NOT ALLOWED",
    37: "AXIS NUMBER MISSING",
    38: "COMMAND PARAMETER MISSING",
}
#: Axis-specific error messages (code = 100 * axis + key), ESP300 manual Appendix A.
AXIS_ERRORS = {
    1: "PARAMETER OUT OF RANGE",
    4: "POSITIVE HARDWARE LIMIT DETECTED",
    5: "NEGATIVE HARDWARE LIMIT DETECTED",
    6: "POSITIVE SOFTWARE LIMIT DETECTED",
    7: "NEGATIVE SOFTWARE LIMIT DETECTED",
    10: "MAXIMUM VELOCITY EXCEEDED",
    11: "MAXIMUM ACCELERATION EXCEEDED",
    13: "MOTOR NOT ENABLED",
    29: "DIGITAL I/O INTERLOCK DETECTED",
}

VERSION = "ESP300 Version 3.08 09/09/02"
SERVO_TICK_S = 400e-6
ERROR_BUFFER_SIZE = 10

#: Longest ``WS`` delay [ms]: the largest 32-bit signed integer (about 24.9 days).  The
#: sections of the ESP300 manual consulted for this emulator (3.4.1, 5.2.12, 5.2.13) give
#: no range for the ``WS`` parameter; this bound is the emulator's decision
#: (docs/protocol.md): it keeps every wait finite while leaving any real warm-up or
#: settling wait (hours) possible.
MAX_WS_DELAY_MS = 2**31 - 1

#: Time over which the slowest allowed motion advances one encoder count [s].  The
#: ESP300 manual (section 5.2.13 "Minimum Velocity", p. 5-11) explains that the minimum
#: usable velocity is set by the encoder resolution and the slowest rate of motion
#: increments, without giving a number; the emulator decides that velocity must be at
#: least one encoder count per second and acceleration at least one count per second
#: squared (:attr:`AxisConfig.min_velocity`, :attr:`AxisConfig.min_acceleration`).
RATE_REFERENCE_TIME_S = 1.0


@dataclass(frozen=True)
class AxisConfig:
    """Static configuration of one axis [deg, deg/s, deg/s^2]."""

    number: int
    name: str
    home: float
    software_limits: tuple[float, float]
    hardware_limits: tuple[float, float]
    velocity: float
    acceleration: float
    max_velocity: float
    max_acceleration: float
    resolution: float = 0.001
    repeatability: float = 0.002

    @property
    def min_velocity(self) -> float:
        """Smallest ``VA`` [deg/s]: one encoder count per :data:`RATE_REFERENCE_TIME_S`.

        With it, the longest possible move (the whole hardware travel, 370 deg on axis 3,
        at 0.001 deg/s) lasts about 3.7e5 s (4.3 days) of simulated time: long, but finite.
        """
        return self.resolution / RATE_REFERENCE_TIME_S

    @property
    def min_acceleration(self) -> float:
        """Smallest ``AC`` [deg/s^2]: one encoder count per :data:`RATE_REFERENCE_TIME_S` squared.

        It bounds the ramp time ``VA / AC`` of a move and of a stop by
        ``max_velocity / min_acceleration`` (4e4 s on axis 3).
        """
        return self.resolution / RATE_REFERENCE_TIME_S**2


DEFAULT_AXES = (
    AxisConfig(1, "camera swing", 0.0, (-90.0, 90.0), (-95.0, 95.0), 10.0, 20.0, 20.0, 80.0),
    AxisConfig(2, "lamp polar angle", 45.0, (0.0, 90.0), (-3.0, 93.0), 15.0, 30.0, 30.0, 120.0),
    AxisConfig(3, "lamp azimuth", 0.0, (-180.0, 180.0), (-185.0, 185.0), 20.0, 40.0, 40.0, 160.0),
)


@dataclass(frozen=True)
class MotionProfile:
    """Piecewise constant-acceleration motion: segments ``(t0, p0, v0, a, duration)``."""

    segments: tuple[tuple[float, float, float, float, float], ...]

    @property
    def start_time(self) -> float:
        return self.segments[0][0]

    @property
    def end_time(self) -> float:
        t0, _, _, _, d = self.segments[-1]
        return t0 + d

    def _segment_at(self, t: float):
        for seg in self.segments:
            if t < seg[0] + seg[4]:
                return seg, max(t - seg[0], 0.0)
        seg = self.segments[-1]
        return seg, seg[4]

    def position(self, t: float) -> float:
        """Position at time ``t`` [deg] (clamped to the start and end of the motion)."""
        (t0, p0, v0, a, d), dt = self._segment_at(t)
        return p0 + v0 * dt + 0.5 * a * dt * dt

    def velocity(self, t: float) -> float:
        """Velocity at time ``t`` [deg/s] (0 after the end)."""
        if t >= self.end_time:
            return 0.0
        (t0, p0, v0, a, d), dt = self._segment_at(t)
        return v0 + a * dt


def _check_motion(name: str, value: float, positive: bool) -> None:
    """Raise ValueError unless ``value`` is finite (and > 0 when ``positive``)."""
    if not math.isfinite(value) or (positive and value <= 0):
        condition = "finite and > 0" if positive else "finite"
        raise ValueError(f"{name} must be {condition}, got {value!r}")


def move_duration(distance: float, velocity: float, acceleration: float) -> float:
    """Duration of a point-to-point move from rest to rest [s].

    Trapezoidal profile ``d/v + v/a`` when the axis reaches ``v`` (``d >= v^2/a``),
    otherwise triangular ``2 sqrt(d/a)``.

    Parameters
    ----------
    distance : float
        Distance of the move [deg], finite.
    velocity : float
        Programmed velocity [deg/s], finite and > 0.
    acceleration : float
        Acceleration and deceleration [deg/s^2], finite and > 0.

    Raises
    ------
    ValueError
        If an argument is not finite or a rate is not positive (the duration would not
        be a finite time).

    Examples
    --------
    >>> move_duration(30.0, 10.0, 20.0), move_duration(1.25, 10.0, 20.0)
    (3.5, 0.5)
    """
    _check_motion("distance", distance, positive=False)
    _check_motion("velocity", velocity, positive=True)
    _check_motion("acceleration", acceleration, positive=True)
    d = abs(distance)
    if d >= velocity * velocity / acceleration:
        duration = d / velocity + velocity / acceleration
    else:
        duration = 2.0 * math.sqrt(d / acceleration)
    _check_motion("the duration of the move", duration, positive=False)  # e.g. a denormal rate
    return duration


def trapezoid_profile(t0: float, start: float, end: float, velocity: float, acceleration: float) -> MotionProfile:
    """Rest-to-rest move from ``start`` to ``end`` [deg] beginning at ``t0`` [s] (see :func:`move_duration`).

    Raises
    ------
    ValueError
        If a time, position or rate is not finite or a rate is not positive.
    """
    for name, value in (("t0", t0), ("start", start), ("end", end)):
        _check_motion(name, value, positive=False)
    _check_motion("velocity", velocity, positive=True)
    _check_motion("acceleration", acceleration, positive=True)
    d = end - start
    s = 1.0 if d >= 0 else -1.0
    dist = abs(d)
    if dist == 0.0:
        return MotionProfile(((t0, start, 0.0, 0.0, 0.0),))
    if dist >= velocity * velocity / acceleration:
        t_acc = velocity / acceleration
        t_flat = dist / velocity - t_acc
        v_peak = velocity
    else:
        t_acc = math.sqrt(dist / acceleration)
        t_flat = 0.0
        v_peak = acceleration * t_acc
    _check_motion("the duration of the move", t0 + 2 * t_acc + t_flat, positive=False)  # e.g. a denormal rate
    p1 = start + s * 0.5 * acceleration * t_acc * t_acc
    p2 = p1 + s * v_peak * t_flat
    return MotionProfile((
        (t0, start, 0.0, s * acceleration, t_acc),
        (t0 + t_acc, p1, s * v_peak, 0.0, t_flat),
        (t0 + t_acc + t_flat, p2, s * v_peak, -s * acceleration, t_acc),
    ))


def stop_profile(t0: float, position: float, velocity: float, acceleration: float) -> MotionProfile:
    """Decelerate from ``velocity`` [deg/s] at ``position`` [deg] to rest with ``acceleration`` [deg/s^2].

    Raises
    ------
    ValueError
        If an argument is not finite or the acceleration is not positive.
    """
    for name, value in (("t0", t0), ("position", position), ("velocity", velocity)):
        _check_motion(name, value, positive=False)
    _check_motion("acceleration", acceleration, positive=True)
    if velocity == 0.0:
        return MotionProfile(((t0, position, 0.0, 0.0, 0.0),))
    duration = abs(velocity) / acceleration
    _check_motion("the duration of the stop", duration, positive=False)
    return MotionProfile(((t0, position, velocity, -math.copysign(acceleration, velocity), duration),))


@dataclass
class AxisState:
    """Mutable state of one axis."""

    config: AxisConfig
    motor_on: bool = False
    velocity: float = 0.0
    acceleration: float = 0.0
    left_limit: float = 0.0
    right_limit: float = 0.0
    desired: float = 0.0
    profile: MotionProfile = field(default=None)  # type: ignore[assignment]
    pending_error: int | None = None  # queued when the current motion ends

    def __post_init__(self) -> None:
        c = self.config
        self.velocity, self.acceleration = c.velocity, c.acceleration
        self.left_limit, self.right_limit = c.software_limits
        self.desired = c.home
        self.profile = MotionProfile(((0.0, c.home, 0.0, 0.0, 0.0),))

    def position(self, t: float) -> float:
        return self.profile.position(t)

    def moving(self, t: float) -> bool:
        return t < self.profile.end_time

    def target(self) -> float:
        """Where the axis will be at rest (true end point of the current motion)."""
        return self.profile.position(self.profile.end_time)

    def encoder_reading(self, t: float) -> float:
        """Position at time ``t`` as the encoder reads it: rounded to the resolution [deg]."""
        res = self.config.resolution
        return round(self.position(t) / res) * res


class _EspError(Exception):
    def __init__(self, code: int) -> None:
        self.code = code
        super().__init__(code)


# ASCII classes only: a Unicode digit is not a number and a non-ASCII space is not a blank.
_COMMAND = re.compile(r"^(\d*)([A-Za-z]{2})(.*)$", re.ASCII)
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$", re.ASCII)
_BLANKS = re.compile(r"[ \t]+")  # manual 3.4.1, p. 3-8: blank spaces are ignored (space and tab)
_QUERIES_WITHOUT_MARK = {"TP", "TE", "TB", "VE"}


def _fmt(value: float) -> str:
    return f"{value:.5f}"


class Esp300Firmware:
    """The ESP300 command interpreter and motion simulation.

    Parameters
    ----------
    clock : SimClock
        Shared simulated clock.
    rng : numpy.random.Generator
        Source of the repeatability errors.
    interlock : callable, optional
        ``interlock((a1, a2, a3)) -> bool``: True when the end point of a move is allowed
        (camera-lamp separation); None allows everything.
    axes : sequence of AxisConfig
        Axis configuration (default :data:`DEFAULT_AXES`).
    baudrate : int
        Line speed, for the transfer time of each line [bit/s].

    Examples
    --------
    >>> fw = Esp300Firmware(SimClock(), np.random.default_rng(0))
    >>> fw.handle_line("1MO;1PA30;1WS;1MD?")
    b'1\\r\\n'
    >>> round(fw.clock.now(), 3)     # trapezoid: 30/10 + 10/20 s
    3.5
    """

    reply_terminator = b"\r\n"

    def __init__(self, clock: SimClock, rng: np.random.Generator,
                 interlock: Callable[[tuple[float, ...]], bool] | None = None,
                 axes: Sequence[AxisConfig] = DEFAULT_AXES, baudrate: int = 19200) -> None:
        self.clock = clock
        self.rng = rng
        self.interlock = interlock
        self.baudrate = baudrate
        self.axes = {c.number: AxisState(c) for c in axes}
        self.errors: list[tuple[int, int]] = []
        self.limit_faults: set[int] = set()

    # -- state ------------------------------------------------------------------------
    def _update(self, t: float) -> None:
        """Settle the motions that ended by time ``t``: a hardware-limit stop queues its error."""
        for axis in self.axes.values():
            if axis.pending_error is not None and not axis.moving(t):
                self._end_limit_stop(axis)

    def _end_limit_stop(self, axis: AxisState) -> None:
        """A move stopped by a hardware limit switch has ended.

        Like a real controller, which aborts the trajectory where the switch trips, the
        axis's desired position becomes the position where it stopped (its encoder
        reading), so ``DP?``/``PA?`` report the stop position and a following ``PR``
        moves relative to it.  It is set when the motion ends, not at command time:
        queried during the move, ``DP?`` reports the commanded target.
        """
        end = axis.profile.end_time
        axis.desired = axis.encoder_reading(end)
        self._push(axis.pending_error, end)
        axis.pending_error = None

    def true_positions(self, t: float | None = None) -> tuple[float, ...]:
        """True (continuous) positions of all axes at time ``t`` [deg]."""
        t = self.clock.now() if t is None else t
        return tuple(self.axes[n].position(t) for n in sorted(self.axes))

    def _push(self, code: int, t: float | None = None) -> None:
        if len(self.errors) < ERROR_BUFFER_SIZE:
            ticks = int((self.clock.now() if t is None else t) / SERVO_TICK_S)
            self.errors.append((code, ticks))

    @staticmethod
    def message(code: int) -> str:
        """Message text of an error code."""
        if code >= 100:
            return AXIS_ERRORS.get(code % 100, "UNKNOWN ERROR")
        return GENERAL_ERRORS.get(code, "UNKNOWN ERROR")

    # -- line handling ----------------------------------------------------------------
    def handle_line(self, line: str) -> bytes:
        """Process one command line; return the reply bytes (one CR LF line per query)."""
        replies: list[str] = []
        for command in line.split(";"):
            command = _BLANKS.sub("", command)
            if not command:
                continue
            self._update(self.clock.now())
            try:
                reply = self._execute(command)
            except _EspError as error:
                self._push(error.code)
                continue
            if reply is not None:
                replies.append(reply)
        return b"".join(r.encode("ascii") + self.reply_terminator for r in replies)

    def internal_error(self, error: Exception) -> bytes:
        """An unexpected failure while executing a line: error 27 (COMMAND NOT ALLOWED), no reply."""
        self._push(27)
        return b""

    def overlong_line(self) -> bytes:
        """A line longer than the input buffer: error 6, no reply."""
        self._push(6)
        return b""

    def _axis(self, digits: str, required: bool = True) -> AxisState | None:
        if not digits:
            if required:
                raise _EspError(37)
            return None
        number = int(digits)
        if number not in self.axes:
            raise _EspError(9)
        return self.axes[number]

    @staticmethod
    def _number(text: str, axis: AxisState | None) -> float:
        if text == "":
            raise _EspError(38)
        if not _NUMBER.match(text):
            raise _EspError(100 * axis.config.number + 1 if axis else 7)
        return float(text)

    def _execute(self, command: str) -> str | None:
        match = _COMMAND.match(command)
        if not match:
            raise _EspError(6)
        digits, mnemonic, rest = match.group(1), match.group(2).upper(), match.group(3)
        query = rest == "?"
        if mnemonic in _QUERIES_WITHOUT_MARK and rest == "":
            query = True
        handler = getattr(self, f"_cmd_{mnemonic}", None)
        if handler is None:
            raise _EspError(6)
        return handler(digits, rest, query)

    # -- general queries --------------------------------------------------------------
    def _cmd_TE(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        code, _ = self.errors.pop(0) if self.errors else (0, 0)
        return str(code)

    def _cmd_TB(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        if self.errors:
            code, ticks = self.errors.pop(0)
        else:
            code, ticks = 0, int(self.clock.now() / SERVO_TICK_S)
        return f"{code}, {ticks}, {self.message(code)}"

    def _cmd_VE(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        return VERSION

    # -- axis queries -----------------------------------------------------------------
    def _cmd_TP(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        return _fmt(self._axis(digits).encoder_reading(self.clock.now()))

    def _cmd_DP(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        return _fmt(self._axis(digits).desired)

    def _cmd_MD(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        return "0" if self._axis(digits).moving(self.clock.now()) else "1"

    # -- motor power ------------------------------------------------------------------
    def _targets(self, digits: str) -> list[AxisState]:
        axis = self._axis(digits, required=False)
        return [axis] if axis is not None else list(self.axes.values())

    def _cmd_MO(self, digits, rest, query):
        if query:
            return "1" if self._axis(digits).motor_on else "0"
        if rest:
            raise _EspError(6)
        for axis in self._targets(digits):
            axis.motor_on = True
        return None

    def _cmd_MF(self, digits, rest, query):
        if query:
            return "0" if self._axis(digits).motor_on else "1"
        if rest:
            raise _EspError(6)
        t = self.clock.now()
        for axis in self._targets(digits):
            if axis.moving(t):  # motor off: the axis stops where it is
                p = axis.position(t)
                axis.profile = MotionProfile(((t, p, 0.0, 0.0, 0.0),))
                axis.pending_error = None
            axis.motor_on = False
        return None

    # -- moves ------------------------------------------------------------------------
    def _start_move(self, axis: AxisState, target: float) -> None:
        t = self.clock.now()
        n = axis.config.number
        if not axis.motor_on:
            raise _EspError(100 * n + 13)
        if axis.moving(t):
            raise _EspError(27)
        if target > axis.right_limit:
            raise _EspError(100 * n + 6)
        if target < axis.left_limit:
            raise _EspError(100 * n + 7)
        if self.interlock is not None:
            ends = [a.target() for _, a in sorted(self.axes.items())]
            ends[n - 1] = target
            if not self.interlock(tuple(ends)):
                raise _EspError(100 * n + 29)
        start = axis.position(t)
        end = target + axis.config.repeatability * float(self.rng.standard_normal())
        if n in self.limit_faults:  # injected: a limit switch trips half way
            self.limit_faults.discard(n)
            end = start + 0.5 * (target - start)
            axis.pending_error = 100 * n + (4 if target >= start else 5)
        axis.desired = target
        axis.profile = trapezoid_profile(t, start, end, axis.velocity, axis.acceleration)

    def _cmd_PA(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            return _fmt(axis.desired)
        self._start_move(axis, self._number(rest, axis))
        return None

    def _cmd_PR(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            raise _EspError(6)
        self._start_move(axis, axis.desired + self._number(rest, axis))
        return None

    def _cmd_OR(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            raise _EspError(6)
        if rest:
            mode = self._number(rest, axis)
            if mode not in (0, 1, 2, 3, 4, 5, 6):
                raise _EspError(100 * axis.config.number + 1)
        self._start_move(axis, axis.config.home)
        return None

    def _cmd_ST(self, digits, rest, query):
        if query or rest:
            raise _EspError(6)
        t = self.clock.now()
        for axis in self._targets(digits):
            if axis.moving(t):
                axis.profile = stop_profile(t, axis.position(t), axis.profile.velocity(t), axis.acceleration)
                axis.desired = axis.target()
                axis.pending_error = None
        return None

    def _cmd_WS(self, digits, rest, query):
        """Wait for stop, then ``nn`` ms more: ``0 <= nn <= MAX_WS_DELAY_MS``, else error 7."""
        if query:
            raise _EspError(6)
        delay_ms = 0.0
        if rest:
            if not _NUMBER.match(rest) or not 0.0 <= float(rest) <= MAX_WS_DELAY_MS:
                raise _EspError(7)
            delay_ms = float(rest)
        axes = self._targets(digits)
        stop = max([self.clock.now()] + [a.profile.end_time for a in axes])
        self.clock.wait_until(stop + delay_ms * 1e-3)
        self._update(self.clock.now())
        return None

    # -- settings ---------------------------------------------------------------------
    def _setting(self, digits: str, rest: str, query: bool, attribute: str,
                 check: Callable[[AxisState, float], None]) -> str | None:
        axis = self._axis(digits)
        if query:
            return _fmt(getattr(axis, attribute))
        value = self._number(rest, axis)
        check(axis, value)
        setattr(axis, attribute, value)
        return None

    @staticmethod
    def _check_rate(axis: AxisState, value: float, low: float, high: float, above_code: int) -> None:
        """Refuse a rate below ``low`` (x01) or above ``high`` (``above_code``: x10, x11)."""
        n = axis.config.number
        if value > high:  # also an overflowing number such as 1e400 (inf)
            raise _EspError(100 * n + above_code)
        if not value >= low:  # zero, negative and absurdly small (denormal) rates
            raise _EspError(100 * n + 1)

    def _cmd_VA(self, digits, rest, query):
        """Velocity: ``min_velocity <= nn <= max_velocity`` [deg/s], else x01 / x10."""
        def check(axis, value):
            c = axis.config
            self._check_rate(axis, value, c.min_velocity, c.max_velocity, 10)
        return self._setting(digits, rest, query, "velocity", check)

    def _cmd_AC(self, digits, rest, query):
        """Acceleration: ``min_acceleration <= nn <= max_acceleration`` [deg/s^2], else x01 / x11."""
        def check(axis, value):
            c = axis.config
            self._check_rate(axis, value, c.min_acceleration, c.max_acceleration, 11)
        return self._setting(digits, rest, query, "acceleration", check)

    def _cmd_SL(self, digits, rest, query):
        def check(axis, value):
            lo, hi = axis.config.hardware_limits
            if not lo <= value <= hi or value > axis.right_limit:
                raise _EspError(100 * axis.config.number + 1)
        return self._setting(digits, rest, query, "left_limit", check)

    def _cmd_SR(self, digits, rest, query):
        def check(axis, value):
            lo, hi = axis.config.hardware_limits
            if not lo <= value <= hi or value < axis.left_limit:
                raise _EspError(100 * axis.config.number + 1)
        return self._setting(digits, rest, query, "right_limit", check)

    def _cmd_SN(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            return "7"
        value = self._number(rest, axis)
        if value != 7:
            raise _EspError(100 * axis.config.number + 1)
        return None

    def _cmd_SU(self, digits, rest, query):
        """Encoder resolution [deg per encoder count] (manual, command ``SU``).

        ``xxSU?`` replies the axis's resolution.  The emulated encoders are fixed
        hardware, so ``xxSUnn`` accepts only the axis's own resolution (a no-op) and
        refuses any other value with x01, as ``SN`` accepts only 7.
        """
        axis = self._axis(digits)
        if query:
            return _fmt(axis.config.resolution)
        if self._number(rest, axis) != axis.config.resolution:
            raise _EspError(100 * axis.config.number + 1)
        return None

"""Firmware of the emulated motion controller: a Newport ESP300 dialect with three axes.

Syntax, commands, replies and error codes follow the vendor manual (Newport, "ESP300
Motion Controller/Driver User's Manual", section 3 "Remote mode", 3.4.1 command syntax,
the command descriptions including TE and TB, and Appendix A error messages); the subset
and the emulator's decisions are documented in docs/protocol.md.

Besides moves, limits, units and errors it stores the motor and servo settings
(:data:`SETUP_SETTINGS`, saved by ``SM`` and loaded by ``RS``), moves to a hardware limit
(``MT``) or indefinitely (``MV``), and stores and runs programs (``EP``, ``QP``, ``XX``,
``EX``, ``LP``; manual 3.3, p. 3-3).

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

__all__ = ["AxisConfig", "DEFAULT_AXES", "MotionProfile", "trapezoid_profile", "move_duration", "crossing_time",
           "Esp300Firmware", "GENERAL_ERRORS", "AXIS_ERRORS", "MAX_WS_DELAY_MS", "RATE_REFERENCE_TIME_S",
           "ANGULAR_UNITS", "MAX_COMMAND_LINE",
           "SETUP_SETTINGS", "SetupSetting", "MAX_PROGRAMS", "PROGRAM_MEMORY"]

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
    0: "MOTOR TYPE NOT DEFINED",
    13: "MOTOR NOT ENABLED",
    27: "INVALID TRAJECTORY MODE FOR HOMING",
    29: "DIGITAL I/O INTERLOCK DETECTED",
    32: "INVALID TRAJECTORY MODE FOR MOVING",
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
    model: str = "GONIO-ROT"
    serial_number: str = "SN0001"

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
    AxisConfig(1, "camera swing", 0.0, (-90.0, 90.0), (-95.0, 95.0), 10.0, 20.0, 20.0, 80.0,
               model="GONIO-SWING", serial_number="SN0101"),
    AxisConfig(2, "lamp polar angle", 45.0, (0.0, 90.0), (-3.0, 93.0), 15.0, 30.0, 30.0, 120.0,
               model="GONIO-POLAR", serial_number="SN0102"),
    AxisConfig(3, "lamp azimuth", 0.0, (-180.0, 180.0), (-185.0, 185.0), 20.0, 40.0, 40.0, 160.0,
               model="GONIO-AZIMUTH", serial_number="SN0103"),
)

#: ``SN`` unit codes accepted by the rotary axes and their size [deg per unit]; 0 (encoder
#: count) is the axis's resolution.  The linear units 1 to 6 (motor step, millimetre to
#: micro-inch) do not apply to a rotary DC-servo stage and are refused with x01.
ANGULAR_UNITS = {0: None, 7: 1.0, 8: 0.9, 9: 180.0 / math.pi, 10: 0.18 / math.pi, 11: 1.8e-4 / math.pi}

#: Longest command line [characters, terminator excluded], manual 3.4.1 p. 3-8 ("The maximum
#: number of characters allowed on a command line is 80").
MAX_COMMAND_LINE = 80


@dataclass(frozen=True)
class MotionProfile:
    """Piecewise motion: segments ``(t0, p0, v0, a, duration)`` of constant acceleration, or
    ``(t0, p0, v0, a0, duration, jerk)`` of constant jerk (an S-curve's, :func:`scurve_profile`)."""

    segments: tuple[tuple[float, ...], ...]

    @property
    def start_time(self) -> float:
        return self.segments[0][0]

    @property
    def end_time(self) -> float:
        return self.segments[-1][0] + self.segments[-1][4]

    def _segment_at(self, t: float):
        for seg in self.segments:
            if t < seg[0] + seg[4]:
                return seg, max(t - seg[0], 0.0)
        seg = self.segments[-1]
        return seg, seg[4]

    def position(self, t: float) -> float:
        """Position at time ``t`` [deg] (clamped to the start and end of the motion)."""
        (t0, p0, v0, a, d, *jerk), dt = self._segment_at(t)
        cubic = jerk[0] * dt**3 / 6.0 if jerk else 0.0
        return p0 + v0 * dt + 0.5 * a * dt * dt + cubic

    def velocity(self, t: float) -> float:
        """Velocity at time ``t`` [deg/s] (0 after the end)."""
        if t >= self.end_time:
            return 0.0
        (t0, p0, v0, a, d, *jerk), dt = self._segment_at(t)
        return v0 + a * dt + (0.5 * jerk[0] * dt * dt if jerk else 0.0)


def _check_motion(name: str, value: float, positive: bool) -> None:
    """Raise ValueError unless ``value`` is finite (and > 0 when ``positive``)."""
    if not math.isfinite(value) or (positive and value <= 0):
        condition = "finite and > 0" if positive else "finite"
        raise ValueError(f"{name} must be {condition}, got {value!r}")


def move_duration(distance: float, velocity: float, acceleration: float, deceleration: float | None = None) -> float:
    """Duration of a point-to-point move from rest to rest [s].

    Trapezoidal profile ``d/v + v/(2a) + v/(2b)`` when the axis reaches ``v``
    (``d >= v^2/(2a) + v^2/(2b)``), otherwise triangular ``sqrt(2d (a + b) / (a b))``;
    ``b`` is the deceleration (default: the acceleration, giving ``d/v + v/a`` and
    ``2 sqrt(d/a)``).

    Parameters
    ----------
    distance : float
        Distance of the move [deg], finite.
    velocity : float
        Programmed velocity [deg/s], finite and > 0.
    acceleration : float
        Acceleration [deg/s^2], finite and > 0.
    deceleration : float, optional
        Deceleration [deg/s^2], finite and > 0 (default: ``acceleration``).

    Raises
    ------
    ValueError
        If an argument is not finite or a rate is not positive (the duration would not
        be a finite time).

    Examples
    --------
    >>> move_duration(30.0, 10.0, 20.0), move_duration(1.25, 10.0, 20.0)
    (3.5, 0.5)
    >>> move_duration(30.0, 10.0, 20.0, 10.0)   # slower deceleration: 0.25 s longer
    3.75
    """
    deceleration = acceleration if deceleration is None else deceleration
    _check_motion("distance", distance, positive=False)
    _check_motion("velocity", velocity, positive=True)
    _check_motion("acceleration", acceleration, positive=True)
    _check_motion("deceleration", deceleration, positive=True)
    d = abs(distance)
    ramps = 0.5 * velocity * velocity * (1.0 / acceleration + 1.0 / deceleration)
    if d >= ramps:
        duration = (d - ramps) / velocity + velocity / acceleration + velocity / deceleration
    else:
        duration = math.sqrt(2.0 * d * (acceleration + deceleration) / (acceleration * deceleration))
    _check_motion("the duration of the move", duration, positive=False)  # e.g. a denormal rate
    return duration


def trapezoid_profile(t0: float, start: float, end: float, velocity: float, acceleration: float,
                      deceleration: float | None = None) -> MotionProfile:
    """Rest-to-rest move from ``start`` to ``end`` [deg] beginning at ``t0`` [s] (see :func:`move_duration`).

    Raises
    ------
    ValueError
        If a time, position or rate is not finite or a rate is not positive.
    """
    deceleration = acceleration if deceleration is None else deceleration
    for name, value in (("t0", t0), ("start", start), ("end", end)):
        _check_motion(name, value, positive=False)
    _check_motion("velocity", velocity, positive=True)
    _check_motion("acceleration", acceleration, positive=True)
    _check_motion("deceleration", deceleration, positive=True)
    d = end - start
    s = 1.0 if d >= 0 else -1.0
    dist = abs(d)
    if dist == 0.0:
        return MotionProfile(((t0, start, 0.0, 0.0, 0.0),))
    ramps = 0.5 * velocity * velocity * (1.0 / acceleration + 1.0 / deceleration)
    if dist >= ramps:
        v_peak = velocity
        t_flat = (dist - ramps) / velocity
    else:
        v_peak = math.sqrt(2.0 * dist * acceleration * deceleration / (acceleration + deceleration))
        t_flat = 0.0
    t_acc, t_dec = v_peak / acceleration, v_peak / deceleration
    _check_motion("the duration of the move", t0 + t_acc + t_flat + t_dec, positive=False)  # e.g. a denormal rate
    p1 = start + s * 0.5 * acceleration * t_acc * t_acc
    p2 = p1 + s * v_peak * t_flat
    return MotionProfile((
        (t0, start, 0.0, s * acceleration, t_acc),
        (t0 + t_acc, p1, s * v_peak, 0.0, t_flat),
        (t0 + t_acc + t_flat, p2, s * v_peak, -s * deceleration, t_dec),
    ))


def _jerk_limited_ramp(speed: float, acceleration: float, jerk: float) -> tuple[float, float]:
    """Peak acceleration [deg/s^2] and duration [s] of a jerk-limited ramp from rest to ``speed``.

    The acceleration rises at ``jerk`` to at most ``acceleration``, stays, and falls at
    ``jerk`` to 0 when the velocity reaches ``speed``; a ramp too short to reach
    ``acceleration`` peaks at ``sqrt(speed jerk)``. Its distance is ``speed * duration / 2``.
    """
    peak = min(acceleration, math.sqrt(speed * jerk))
    return peak, (speed / peak + peak / jerk) if speed > 0 else 0.0


def scurve_profile(t0: float, start: float, end: float, velocity: float, acceleration: float,
                   deceleration: float, jerk: float) -> MotionProfile:
    """Rest-to-rest S-curve move (``TJ2``) from ``start`` to ``end`` [deg] beginning at ``t0`` [s].

    The trapezoid of :func:`trapezoid_profile` with its corners rounded by a jerk limit
    [deg/s^3] (manual command ``JK``: the rate of change of the acceleration): up to seven
    segments of constant jerk; the peak velocity is ``velocity`` or, for a short move, the
    one whose two ramps cover the distance (solved with :func:`scipy.optimize.brentq`).
    A large jerk gives the trapezoid back.

    >>> move = scurve_profile(0.0, 0.0, 30.0, 10.0, 20.0, 20.0, 200.0)
    >>> round(move.end_time, 6), round(move.position(move.end_time), 9)   # trapezoid's 3.5 s + a / jerk
    (3.6, 30.0)
    >>> move.velocity(0.0), round(move.velocity(1.8), 9), round(move.position(1.8), 9)
    (0.0, 10.0, 15.0)
    """
    for name, value in (("t0", t0), ("start", start), ("end", end)):
        _check_motion(name, value, positive=False)
    for name, value in (("velocity", velocity), ("acceleration", acceleration), ("deceleration", deceleration),
                        ("jerk", jerk)):
        _check_motion(name, value, positive=True)
    distance = abs(end - start)
    if distance == 0.0:
        return MotionProfile(((t0, start, 0.0, 0.0, 0.0),))

    def ramps(speed: float) -> float:  # distance of both ramps at peak velocity ``speed``
        return 0.5 * speed * (_jerk_limited_ramp(speed, acceleration, jerk)[1]
                              + _jerk_limited_ramp(speed, deceleration, jerk)[1])

    peak = velocity
    if ramps(velocity) > distance:
        from scipy.optimize import brentq

        peak = brentq(lambda speed: ramps(speed) - distance, 0.0, velocity, xtol=1e-15, rtol=1e-14)
    a_up, t_up = _jerk_limited_ramp(peak, acceleration, jerk)
    a_down, t_down = _jerk_limited_ramp(peak, deceleration, jerk)
    cruise = max(distance - 0.5 * peak * (t_up + t_down), 0.0) / peak
    pieces = []  # (duration, jerk) along the direction of motion
    for rate, ramp_time, sign in ((a_up, t_up, 1.0), (a_down, t_down, -1.0)):
        corner = rate / jerk
        pieces += [(corner, sign * jerk), (ramp_time - 2.0 * corner, 0.0), (corner, -sign * jerk)]
        if sign > 0:
            pieces.append((cruise, 0.0))
    direction = 1.0 if end >= start else -1.0
    segments, t, p, v, a = [], t0, start, 0.0, 0.0
    for duration, j in pieces:
        duration = max(duration, 0.0)
        segments.append((t, p, v, a, duration, direction * j))
        p += v * duration + 0.5 * a * duration**2 + direction * j * duration**3 / 6.0
        v += a * duration + 0.5 * direction * j * duration**2
        a += direction * j * duration
        t += duration
    _check_motion("the duration of the move", t, positive=False)
    return MotionProfile(tuple(segments))


def profile_from_state(t0: float, start: float, speed: float, end: float, velocity: float, acceleration: float,
                       deceleration: float) -> MotionProfile:
    """A move to rest at ``end`` [deg] from ``start`` at velocity ``speed`` [deg/s] (signed)
    at time ``t0`` [s]: what the ESP300 does with a ``PA`` or ``PR`` received while the axis
    moves, or with ``VA``, ``AC``, ``AG`` changed during a move (manual, ``PA``/``PR``,
    p. 3-112: usage "MIP", accepted while a motion is in progress).

    Toward the target with room to stop: accelerate (``acceleration``) to ``velocity``, or
    slow down to it (``deceleration``) when moving faster, cruise, decelerate to rest at
    ``end``; a shorter distance peaks below ``velocity``. Moving away from the target, or too
    fast to stop before it: decelerate to rest first, then a rest-to-rest move back
    (:func:`trapezoid_profile`; the manual's caution against reversing a motion).
    Position and velocity are continuous at ``t0``.

    >>> profile = profile_from_state(0.0, 10.0, 5.0, 20.0, 5.0, 10.0, 10.0)
    >>> profile.position(0.0), profile.velocity(0.0), profile.position(profile.end_time)
    (10.0, 5.0, 20.0)
    """
    for name, value in (("t0", t0), ("start", start), ("speed", speed), ("end", end)):
        _check_motion(name, value, positive=False)
    for name, value in (("velocity", velocity), ("acceleration", acceleration), ("deceleration", deceleration)):
        _check_motion(name, value, positive=True)
    distance = end - start
    direction = 1.0 if distance >= 0 else -1.0
    toward = speed * direction  # speed toward the target (negative: away from it)
    stopping = speed * speed / (2.0 * deceleration)
    if speed == 0.0:
        return trapezoid_profile(t0, start, end, velocity, acceleration, deceleration)
    if toward < 0 or stopping >= abs(distance):  # stop first, then come back (or not at all)
        t_stop = abs(speed) / deceleration
        stop_at = start + speed * t_stop / 2.0
        back = trapezoid_profile(t0 + t_stop, stop_at, end, velocity, acceleration, deceleration)
        return MotionProfile(((t0, start, speed, -math.copysign(deceleration, speed), t_stop),) + back.segments)
    return _moving_trapezoid(t0, start, toward, abs(distance), direction, velocity, acceleration, deceleration)


def _moving_trapezoid(t0: float, start: float, u0: float, distance: float, direction: float, velocity: float,
                      acceleration: float, deceleration: float) -> MotionProfile:
    """The segments of :func:`profile_from_state` toward the target at speed ``u0 > 0`` with
    room to stop (``u0^2 / 2d <= distance``)."""
    if u0 > velocity:  # slow down to the new velocity, cruise, stop
        peak, rate_in = velocity, deceleration
    else:
        full = (velocity**2 - u0**2) / (2 * acceleration) + velocity**2 / (2 * deceleration)
        peak = velocity if distance >= full else math.sqrt(
            (2 * acceleration * distance + u0**2) * deceleration / (acceleration + deceleration))
        rate_in = acceleration
    t_in = abs(peak - u0) / rate_in
    d_in = (peak**2 - u0**2) / (2 * (rate_in if peak >= u0 else -rate_in))
    d_out = peak**2 / (2 * deceleration)
    t_flat = max(distance - d_in - d_out, 0.0) / peak if peak > 0 else 0.0
    t_out = peak / deceleration
    p1 = start + direction * d_in
    p2 = p1 + direction * peak * t_flat
    return MotionProfile((
        (t0, start, direction * u0, direction * math.copysign(rate_in, peak - u0), t_in),
        (t0 + t_in, p1, direction * peak, 0.0, t_flat),
        (t0 + t_in + t_flat, p2, direction * peak, -direction * deceleration, t_out),
    ))


def crossing_time(profile: MotionProfile, position: float, after: float) -> float | None:
    """First time >= ``after`` at which ``profile`` passes ``position`` [s], None if it never does.

    Examples
    --------
    >>> move = trapezoid_profile(0.0, 0.0, 30.0, 10.0, 20.0)
    >>> round(crossing_time(move, 15.0, 0.0), 6)       # half way of a symmetric move
    1.75
    >>> crossing_time(move, 40.0, 0.0) is None
    True
    >>> round(crossing_time(scurve_profile(0.0, 0.0, 30.0, 10.0, 20.0, 20.0, 200.0), 15.0, 0.0), 6)
    1.8
    """
    best = None
    for t0, p0, v0, a, duration, *jerk in profile.segments:
        lo = max(after - t0, 0.0)
        if lo > duration:
            continue
        c = p0 - position
        if jerk and jerk[0] != 0.0:
            roots = [r.real for r in np.roots([jerk[0] / 6.0, 0.5 * a, v0, c]) if abs(r.imag) < 1e-9]
        elif a == 0.0:
            roots = [-c / v0] if v0 != 0.0 else ([lo] if c == 0.0 else [])
        else:
            disc = v0 * v0 - 2.0 * a * c
            if disc < 0:
                continue
            r = math.sqrt(disc)
            roots = [(-v0 - r) / a, (-v0 + r) / a]
        valid = [t0 + dt for dt in roots if lo - 1e-12 <= dt <= duration + 1e-12]
        if valid:
            best = min(valid)
            break
    return best


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

#: Largest gain or feed-forward factor (manual, command ``KP``, p. 3-93: 0 to 2e9).
MAX_GAIN = 2e9


@dataclass(frozen=True)
class SetupSetting:
    """A motor or servo setting of an axis that the firmware stores (docs/protocol.md).

    Attributes
    ----------
    mnemonic : str
        Two-letter command, e.g. ``"KP"``.
    kind : str
        ``"units"`` (a position, velocity, acceleration or jerk in the axis's ``SN`` units,
        stored in degrees), ``"real"`` (a unitless factor or a current or voltage),
        ``"integer"`` or ``"hex"`` (a bit field, written and read in hexadecimal).
    default : callable
        ``default(config) -> value``: the power-on value [deg-based for ``"units"``].
    low, high : callable
        ``low(axis)``, ``high(axis)``: the accepted range [deg-based for ``"units"``].
    above_code : int
        Axis error key for a value above ``high`` (1 PARAMETER OUT OF RANGE, 10 MAXIMUM
        VELOCITY EXCEEDED); below ``low`` is always 1.
    """

    mnemonic: str
    kind: str
    default: Callable[[AxisConfig], float]
    low: Callable[["AxisState"], float]
    high: Callable[["AxisState"], float]
    above_code: int = 1


def _constant(value: float) -> Callable:
    return lambda _: value


def _velocity_setting(mnemonic: str, default: Callable[[AxisConfig], float], low=None) -> SetupSetting:
    """A velocity up to ``VU`` (x10 above, x01 below one encoder count per second)."""
    return SetupSetting(mnemonic, "units", default, low or (lambda axis: axis.config.min_velocity),
                        lambda axis: axis.max_velocity, above_code=10)


#: The motor and servo settings behind InstrumentKit's ``setup_axis``/``read_setup``; their
#: ranges and power-on values, and which of them act on the emulated motion, are listed in
#: docs/protocol.md ("Motor and servo settings").
SETUP_SETTINGS = {spec.mnemonic: spec for spec in (
    SetupSetting("JK", "units", lambda c: 10.0 * c.max_acceleration, lambda a: a.config.resolution,
                 _constant(MAX_GAIN)),
    _velocity_setting("VB", _constant(0.0), low=_constant(0.0)),
    _velocity_setting("JH", lambda c: 0.5 * c.max_velocity),
    _velocity_setting("JW", lambda c: 0.1 * c.max_velocity),
    SetupSetting("FR", "units", lambda c: c.resolution, lambda a: 1e-9, _constant(MAX_GAIN)),
    SetupSetting("FE", "units", _constant(1.0), lambda a: a.config.resolution, _constant(MAX_GAIN)),
    SetupSetting("QI", "real", _constant(1.0), _constant(0.0), _constant(3.0)),
    SetupSetting("QV", "real", _constant(24.0), _constant(0.0), _constant(48.0)),
    SetupSetting("QM", "integer", _constant(1), _constant(0), _constant(1)),
    SetupSetting("QS", "integer", _constant(10), _constant(1), _constant(250)),
    SetupSetting("KP", "real", _constant(0.005), _constant(0.0), _constant(MAX_GAIN)),
    SetupSetting("KI", "real", _constant(0.0001), _constant(0.0), _constant(MAX_GAIN)),
    SetupSetting("KD", "real", _constant(0.02), _constant(0.0), _constant(MAX_GAIN)),
    SetupSetting("KS", "real", _constant(0.5), _constant(0.0), _constant(MAX_GAIN)),
    SetupSetting("AF", "real", _constant(0.0), _constant(0.0), _constant(MAX_GAIN)),
    SetupSetting("FP", "integer", _constant(3), _constant(0), _constant(7)),
    SetupSetting("TJ", "integer", _constant(1), _constant(1), _constant(6)),
    SetupSetting("ZB", "hex", _constant(0x110), _constant(0), _constant(0xFFFF)),
    SetupSetting("ZH", "hex", _constant(0x24), _constant(0), _constant(0xFFFF)),
    SetupSetting("ZS", "hex", _constant(0x0), _constant(0), _constant(0xFFFF)),
)}

#: Home search modes (``OR``, ``OM``; manual command ``OR``): what the search looks for, and
#: whether it ends on the encoder's index pulse (True: exactly, to one count) or on the
#: switch's edge (False: within the axis's repeatability).
HOMING_MODES = {
    0: ("zero", True),    # the controller's +0 position count
    1: ("home", True),    # home switch and index pulse (power-on mode)
    2: ("home", False),   # home switch only
    3: ("+limit", False),  # positive hardware limit switch
    4: ("-limit", False),  # negative hardware limit switch
    5: ("+limit", True),  # positive limit switch and index pulse
    6: ("-limit", True),  # negative limit switch and index pulse
}
DEFAULT_HOMING_MODE = 1

#: Trajectory modes (``TJ``) the emulated controller moves in: 1 trapezoidal, 2 S-curve.
#: Modes 3 (jog) to 6 (slave to a master axis) are stored; host moves in them are refused.
TRAJECTORY_TRAPEZOID, TRAJECTORY_SCURVE = 1, 2

#: Stored programs (manual 3.3 "Program execution mode", p. 3-3): up to 100 programs in
#: the program memory, 61440 bytes of the controller's 64 kB (manual command ``XM``).
MAX_PROGRAMS = 100
PROGRAM_MEMORY = 61440
#: Bits of the first register of ``PH`` (manual p. 3-111) that read 1 on a controller
#: without an emergency stop pressed: the e-stop inputs of the 100-pin and auxiliary
#: connectors unlatched (bits 27, 28), as in the manual's example ``18000404H, 4H``.
_PH_IDLE_BITS = (1 << 27) | (1 << 28)


@dataclass
class AxisState:
    """Mutable state of one axis."""

    config: AxisConfig
    motor_on: bool = False
    velocity: float = 0.0
    acceleration: float = 0.0
    deceleration: float = 0.0
    estop_deceleration: float = 0.0
    max_velocity: float = 0.0
    max_acceleration: float = 0.0
    homing_velocity: float = 0.0
    homing_low_velocity: float = 0.0
    homing_mode: int = DEFAULT_HOMING_MODE
    left_limit: float = 0.0
    right_limit: float = 0.0
    desired: float = 0.0
    offset: float = 0.0  # controller position minus mechanical angle [deg] (DH, OR)
    home_preset: float = 0.0  # position a home search gives the point it finds (SH, DH) [deg]
    units: int = 7
    profile: MotionProfile = field(default=None)  # type: ignore[assignment]
    pending_error: int | None = None  # queued when the current motion ends
    #: The profile of the move in progress when ``PA`` or ``PR`` started it at ``VA``: such a
    #: move follows a changed ``VA``, ``AC`` or ``AG`` (any other profile, None: it does not).
    retimable: MotionProfile | None = None
    setup: dict[str, float] = field(default_factory=dict)  # motor and servo settings (SETUP_SETTINGS)
    torque_reduction: tuple[int, int] = (0, 0)  # QR: idle time [ms], percentage of the current

    def __post_init__(self) -> None:
        c = self.config
        self.velocity, self.acceleration, self.deceleration = c.velocity, c.acceleration, c.acceleration
        self.estop_deceleration = c.max_acceleration
        self.max_velocity, self.max_acceleration = c.max_velocity, c.max_acceleration
        self.homing_velocity = c.velocity
        self.homing_low_velocity = 0.1 * c.velocity
        self.setup = {spec.mnemonic: spec.default(c) for spec in SETUP_SETTINGS.values()}
        self.left_limit, self.right_limit = c.software_limits
        self.desired = c.home
        self.home_preset = c.home
        self.profile = MotionProfile(((0.0, c.home, 0.0, 0.0, 0.0),))

    def saved_settings(self) -> dict:
        """The settings ``SM`` saves and ``RS`` restores (manual command ``SM``)."""
        names = ("velocity", "acceleration", "deceleration", "estop_deceleration", "max_velocity",
                 "max_acceleration", "homing_velocity", "homing_low_velocity", "homing_mode", "left_limit",
                 "right_limit", "units",
                 "torque_reduction")
        saved = {name: getattr(self, name) for name in names}
        saved["setup"] = dict(self.setup)
        return saved

    def restore(self, saved: dict) -> None:
        """Load settings saved by :meth:`saved_settings`."""
        for name, value in saved.items():
            setattr(self, name, dict(value) if name == "setup" else value)

    @property
    def unit_size(self) -> float:
        """Size of the axis's display unit (``SN``) [deg]."""
        size = ANGULAR_UNITS[self.units]
        return self.config.resolution if size is None else size

    def position(self, t: float) -> float:
        return self.profile.position(t)

    def moving(self, t: float) -> bool:
        return t < self.profile.end_time

    def target(self) -> float:
        """Where the axis will be at rest (true mechanical end point of the current motion) [deg]."""
        return self.profile.position(self.profile.end_time)

    def encoder_reading(self, t: float) -> float:
        """Controller position at time ``t`` as the encoder reads it: rounded to the resolution [deg]."""
        res = self.config.resolution
        return round((self.position(t) + self.offset) / res) * res


class _EspError(Exception):
    def __init__(self, code: int) -> None:
        self.code = code
        super().__init__(code)


# ASCII classes only: a Unicode digit is not a number and a non-ASCII space is not a blank.
_COMMAND = re.compile(r"^(\d*)([A-Za-z]{2})(.*)$", re.ASCII)
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$", re.ASCII)
_BLANKS = re.compile(r"[ \t]+")  # manual 3.4.1, p. 3-8: blank spaces are ignored (space and tab)
_QUERIES_WITHOUT_MARK = {"TP", "TE", "TB", "VE", "TS", "TX", "TV", "DV", "PH", "XM"}
#: Bit 6 of the TS and TX status characters, set (the manual's examples: ``[P``, ``P``), so
#: that the character is printable.
_STATUS_CHARACTER_BASE = 0x40


def _stored_size(command: str) -> int:
    """Program memory taken by a stored command [bytes]: its characters and a separator."""
    return len(command) + 1


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
        self.programs: dict[int, list[str]] = {}
        self.recording: int | None = None  # program number while in program entry mode (EP)
        self.saved: dict[int, dict] = {}  # settings saved by SM, loaded by RS
        self._running_program = False
        self._used_program_memory = 0  # [bytes], see _stored_size
        #: ``(axis, position [units of the controller, deg])`` of a ``WP`` whose position the
        #: axis will not pass: the controller waits for it and executes nothing until reset
        #: (:meth:`power_cycle`); None when it is not waiting.
        self.waiting_for: tuple[int, float] | None = None

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
        """Process one command line; return the reply bytes (one CR LF line per query).

        A line longer than :data:`MAX_COMMAND_LINE` characters (manual 3.4.1) executes
        nothing and queues error 6.
        """
        if self.waiting_for is not None:  # in a WP that never ends: the line stays in the input buffer
            return b""
        if len(line) > MAX_COMMAND_LINE:
            self._push(6)
            return b""
        replies = self._run_commands(line.split(";"))
        return b"".join(r.encode("ascii") + self.reply_terminator for r in replies)

    def _run_commands(self, commands: Sequence[str]) -> list[str]:
        """Execute (or, in program entry mode, store) ``commands``; return the query replies."""
        replies: list[str] = []
        for command in commands:
            if self.waiting_for is not None:  # a WP of this line never ends: the rest waits with it
                break
            command = _BLANKS.sub("", command)
            if not command:
                continue
            if self.recording is not None:
                self._record(command)
                continue
            self._update(self.clock.now())
            try:
                reply = self._execute(command)
            except _EspError as error:
                self._push(error.code)
                continue
            if reply is not None:
                replies.extend(reply if isinstance(reply, list) else [reply])
        return replies

    def _record(self, command: str) -> None:
        """Program entry mode: store ``command`` unevaluated; ``QP`` ends the mode (manual p. 3-3).

        A command that does not fit in the program memory is not stored (error 27).
        """
        if command.upper() == "QP":
            self.recording = None
            return
        if self._used_program_memory + _stored_size(command) > PROGRAM_MEMORY:
            self._push(27)
            return
        self.programs[self.recording].append(command)
        self._used_program_memory += _stored_size(command)

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

    def _quantity(self, text: str, axis: AxisState) -> float:
        """An axis parameter in the axis's units (``SN``), as degrees (or deg/s, deg/s^2)."""
        return self._number(text, axis) * axis.unit_size

    @staticmethod
    def _out(axis: AxisState, degrees: float) -> str:
        """A quantity in degrees as the axis reports it: in its units, 5 decimals."""
        return _fmt(degrees / axis.unit_size)

    def _execute(self, command: str) -> str | list[str] | None:
        match = _COMMAND.match(command)
        if not match:
            raise _EspError(6)
        digits, mnemonic, rest = match.group(1), match.group(2).upper(), match.group(3)
        query = rest == "?"
        if mnemonic in _QUERIES_WITHOUT_MARK and rest == "":
            query = True
        if mnemonic in SETUP_SETTINGS:
            return self._setup_command(digits, rest, query, mnemonic)
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

    def _cmd_ID(self, digits, rest, query):
        """Stage model and serial number (manual p. 3-86): ``xxID?`` -> ``<model>, <serial>``."""
        if not query:
            raise _EspError(6)
        config = self._axis(digits).config
        return f"{config.model}, {config.serial_number}"

    def _cmd_RS(self, digits, rest, query):
        """Reset the controller: every axis stops at once, power-on state (manual command RS).

        The axes keep their mechanical positions; the coordinates return to the power-on
        ones (``DH`` and ``SN`` reset), motors are off and the error buffer is empty.
        """
        if query or rest or digits:
            raise _EspError(6)
        t = self.clock.now()
        for number, axis in list(self.axes.items()):
            fresh = AxisState(axis.config)
            if number in self.saved:
                fresh.restore(self.saved[number])
            position = axis.position(t)
            fresh.profile = MotionProfile(((t, position, 0.0, 0.0, 0.0),))
            fresh.desired = round(position / axis.config.resolution) * axis.config.resolution
            self.axes[number] = fresh
        self.errors.clear()
        self.limit_faults.clear()
        self.recording = None
        return None

    # -- axis queries -----------------------------------------------------------------
    def _cmd_TP(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        axis = self._axis(digits)
        return self._out(axis, axis.encoder_reading(self.clock.now()))

    def _cmd_TS(self, digits, rest, query):
        """Controller status (manual p. 3-142): one character; bits 0-2 axes 1-3 in motion,
        bit 4 the motor of at least one axis on, bit 6 set (:data:`_STATUS_CHARACTER_BASE`)."""
        if not query or digits:
            raise _EspError(6)
        t = self.clock.now()
        bits = sum(1 << (n - 1) for n, axis in self.axes.items() if axis.moving(t))
        bits |= (1 << 4) if any(axis.motor_on for axis in self.axes.values()) else 0
        return chr(_STATUS_CHARACTER_BASE | bits)

    def _cmd_TX(self, digits, rest, query):
        """Controller activity (manual p. 3-144): one character; bit 0 a program executing,
        bit 1 a wait executing, bit 2 manual jog, bit 4 at least one trajectory executing,
        bit 6 set. A query is answered between commands, so bits 0 and 1 read 0 (a program
        or a wait holds the line until it ends) and the emulated rig has no front-panel jog."""
        if not query or digits:
            raise _EspError(6)
        t = self.clock.now()
        moving = any(axis.moving(t) for axis in self.axes.values())
        return chr(_STATUS_CHARACTER_BASE | ((1 << 4) if moving else 0))

    def _cmd_PH(self, digits, rest, query):
        """Hardware status (manual p. 3-111): two registers in hexadecimal, ``18000404H, 4H``.

        First register: bits 0-5 the positive limit switch of axes 1-6, bits 8-13 the
        negative one, 16-21 amplifier faults (none), 27-28 the e-stop inputs unlatched.
        Second: bits 0-5 the home switch of axes 1-6 (1 on the positive side of the home
        angle: the level whose edge a home search finds), 8-13 the index pulses (an
        instant; read 0). An axis prefix is ignored (EPICS sends ``01PH``, bliss ``PH?``).
        """
        if not query:
            raise _EspError(6)
        t = self.clock.now()
        limits, homes = _PH_IDLE_BITS, 0
        for n, axis in self.axes.items():
            angle = axis.position(t)
            lo, hi = axis.config.hardware_limits
            half_count = 0.5 * axis.config.resolution
            limits |= (1 << (n - 1)) if angle >= hi - half_count else 0
            limits |= (1 << (n + 7)) if angle <= lo + half_count else 0
            homes |= (1 << (n - 1)) if angle >= axis.config.home else 0
        return f"{limits:X}H, {homes:X}H"

    def _cmd_XM(self, digits, rest, query):
        """Unused program memory [bytes] (manual command ``XM``), of :data:`PROGRAM_MEMORY`."""
        if not query or digits:
            raise _EspError(6)
        return str(PROGRAM_MEMORY - self._used_program_memory)

    def _cmd_TV(self, digits, rest, query):
        """Actual velocity of the axis now (manual p. 3-143) [units/s]; the servo follows
        the trajectory, so it is the trajectory's velocity."""
        if not query:
            raise _EspError(6)
        axis = self._axis(digits)
        t = self.clock.now()
        return self._out(axis, axis.profile.velocity(t))

    def _cmd_DV(self, digits, rest, query):
        """Desired velocity of the axis's trajectory now (manual p. 3-143, example with
        ``TV``) [units/s]."""
        return self._cmd_TV(digits, rest, query)

    def _cmd_DP(self, digits, rest, query):
        if not query:
            raise _EspError(6)
        axis = self._axis(digits)
        return self._out(axis, axis.desired)

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
    def _check_move(self, axis: AxisState, target: float, software_limits: bool = True,
                    while_moving: bool = False, homing: bool = False) -> None:
        """Refuse a move of ``axis`` to the controller position ``target`` [deg] (see
        docs/protocol.md); ``while_moving``: a command the manual accepts during a motion
        (``PA``, ``PR``: usage "MIP"), which retargets a move ``PA`` or ``PR`` started."""
        n = axis.config.number
        if axis.setup["QM"] == 0:
            raise _EspError(100 * n + 0)
        if not axis.motor_on:
            raise _EspError(100 * n + 13)
        if axis.setup["TJ"] not in (TRAJECTORY_TRAPEZOID, TRAJECTORY_SCURVE):
            raise _EspError(100 * n + (27 if homing else 32))  # jog and slave modes: no host moves
        if axis.moving(self.clock.now()) and not (while_moving and axis.profile is axis.retimable):
            raise _EspError(27)  # a home search, a jog, an S-curve move, a move a limit stops: not retargeted
        if software_limits and target > axis.right_limit:
            raise _EspError(100 * n + 6)
        if software_limits and target < axis.left_limit:
            raise _EspError(100 * n + 7)
        if self.interlock is not None:  # on the commanded targets (docs/protocol.md), not where the axes will land
            ends = [a.desired - a.offset for _, a in sorted(self.axes.items())]
            ends[n - 1] = target - axis.offset
            if not self.interlock(tuple(ends)):
                raise _EspError(100 * n + 29)

    def _start_move(self, axis: AxisState, target: float, velocity: float | None = None,
                    while_moving: bool = False, on_switch: bool = False, homing: bool = False) -> None:
        """Move ``axis`` to the controller position ``target`` [deg] at ``velocity`` (default
        ``VA``); ``while_moving``: from its present position and speed if it moves (``PA``,
        ``PR``, :func:`profile_from_state`); ``on_switch``: the move ends where the home
        switch and the encoder's index pulse are, exactly (``OR``: repeatable to one count),
        instead of within the axis's repeatability of the target; ``homing``: a home search,
        which goes to its switch whatever the software limits ``SL``/``SR``."""
        self._check_move(axis, target, software_limits=not homing, while_moving=while_moving, homing=homing)
        t = self.clock.now()
        n = axis.config.number
        start = axis.position(t)
        speed = axis.profile.velocity(t) if axis.moving(t) else 0.0
        draw = float(self.rng.standard_normal())  # drawn for every move: the seed's sequence stays as it was
        scatter = 0.0 if on_switch else axis.config.repeatability * draw
        end = target - axis.offset + scatter
        if n in self.limit_faults:  # injected: a limit switch trips half way
            self.limit_faults.discard(n)
            end = start + 0.5 * (target - axis.offset - start)
            axis.pending_error = 100 * n + (4 if end >= start else 5)
        axis.desired = target
        if axis.setup["TJ"] == TRAJECTORY_SCURVE:  # from rest: a retarget of an S-curve move was refused
            axis.profile = self._rest_to_rest(axis, t, start, end, velocity or axis.velocity)
            axis.retimable = None
        else:
            axis.profile = profile_from_state(t, start, speed, end, velocity or axis.velocity, axis.acceleration,
                                              axis.deceleration)
            axis.retimable = axis.profile if velocity is None and axis.pending_error is None else None

    def _cmd_PA(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            return self._out(axis, axis.desired)
        self._start_move(axis, self._quantity(rest, axis), while_moving=True)
        return None

    def _cmd_PR(self, digits, rest, query):
        axis = self._axis(digits)
        if query:
            raise _EspError(6)
        self._start_move(axis, axis.desired + self._quantity(rest, axis), while_moving=True)
        return None

    def _cmd_OR(self, digits, rest, query):
        """Home search (manual command ``OR``) in mode ``nn`` (0 to 6), or without ``nn`` in the
        mode set with ``OM`` (power-on: 1), at the homing velocity ``OH``.

        The search goes to what its mode looks for (:data:`HOMING_MODES`: the controller's
        zero count, the home switch, a hardware limit switch), past the software limits,
        and the point found is given the home preset (``SH``, ``DH``; power-on: the home
        angle) from this command on. It ends there exactly when the mode uses the
        encoder's index pulse, within the axis's repeatability on a switch's edge alone.
        Reaching a limit switch is the search's end, not an error.
        """
        axis = self._axis(digits)
        if query:
            raise _EspError(6)
        mode = self._homing_mode(rest, axis) if rest else axis.homing_mode
        looks_for, on_index = HOMING_MODES[mode]
        previous, axis.offset = axis.offset, axis.home_preset - self._homing_point(axis, looks_for)
        try:
            self._start_move(axis, axis.home_preset, axis.homing_velocity, on_switch=on_index, homing=True)
        except _EspError:
            axis.offset = previous  # a refused home search changes nothing
            raise
        return None

    def _homing_mode(self, text: str, axis: AxisState) -> int:
        """A home search mode 0 to 6 (manual commands ``OR``, ``OM``), else x01."""
        mode = self._number(text, axis)
        if mode not in HOMING_MODES:
            raise _EspError(100 * axis.config.number + 1)
        return int(mode)

    @staticmethod
    def _homing_point(axis: AxisState, looks_for: str) -> float:
        """The mechanical angle [deg] a home search looking for ``looks_for`` ends at."""
        lo, hi = axis.config.hardware_limits
        return {"zero": -axis.offset, "home": axis.config.home, "+limit": hi, "-limit": lo}[looks_for]

    def _cmd_OM(self, digits, rest, query):
        """Home search mode of a bare ``OR`` (0 to 6, :data:`HOMING_MODES`; power-on 1)."""
        axis = self._axis(digits)
        if query:
            return str(axis.homing_mode)
        axis.homing_mode = self._homing_mode(rest, axis)
        return None

    def _cmd_SH(self, digits, rest, query):
        """Home preset [units]: the position a home search gives the point it finds (manual
        command ``SH``; power-on: the home angle). ``DH`` sets it too."""
        axis = self._axis(digits)
        if query:
            return self._out(axis, axis.home_preset)
        axis.home_preset = self._quantity(rest, axis)
        return None

    def _cmd_DH(self, digits, rest, query):
        """Define home: the current position becomes ``nn`` (default 0) [units]; ``DH?`` reads it back.

        Refused with 27 while the axis moves.  Software limits keep their values in the new
        coordinates.
        """
        axis = self._axis(digits)
        if query:
            return self._out(axis, axis.home_preset)
        value = self._quantity(rest, axis) if rest else 0.0
        t = self.clock.now()
        if axis.moving(t):
            raise _EspError(27)
        shift = value - axis.encoder_reading(t)
        axis.offset += shift
        axis.desired += shift
        axis.home_preset = value
        return None

    def _stop(self, axes: list[AxisState], deceleration_of: Callable[[AxisState], float]) -> None:
        t = self.clock.now()
        for axis in axes:
            if axis.moving(t):
                axis.profile = stop_profile(t, axis.position(t), axis.profile.velocity(t), deceleration_of(axis))
                axis.desired = axis.target() + axis.offset
                axis.pending_error = None

    def _cmd_ST(self, digits, rest, query):
        """Stop axis ``xx`` (all axes without ``xx``) with its deceleration ``AG``."""
        if query or rest:
            raise _EspError(6)
        self._stop(self._targets(digits), lambda axis: axis.deceleration)
        return None

    def _cmd_AB(self, digits, rest, query):
        """Abort motion: every axis stops with its e-stop deceleration ``AE`` and its motor is
        switched off (a software emergency stop; an axis prefix is ignored)."""
        if query or rest:
            raise _EspError(6)
        axes = list(self.axes.values())
        self._stop(axes, lambda axis: axis.estop_deceleration)
        for axis in axes:
            axis.motor_on = False
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

    def _cmd_WP(self, digits, rest, query):
        """Wait for position: hold command processing until axis ``xx`` passes ``nn`` [units].

        The wait ends when the trajectory passes ``nn``, or, for ``nn`` within one encoder
        count of the commanded target, when the move ends there (the servo's trajectory
        ends at the commanded target; the landing point differs from it by the
        repeatability), as after ``PA`` then ``WP`` to the same position. For a position the
        axis will not pass the controller waits as the hardware does: it executes nothing
        more (the rest of the line, later lines), answers nothing, so a client sees its own
        read timeout, until the controller is reset (:meth:`power_cycle`, the control
        channel's ``power_cycle``).
        """
        axis = self._axis(digits)
        if query:
            raise _EspError(6)
        position = self._quantity(rest, axis)
        t = self.clock.now()
        when = crossing_time(axis.profile, position - axis.offset, t)
        if when is None and abs(position - axis.desired) <= axis.config.resolution:
            when = axis.profile.end_time
        if when is None:
            self.waiting_for = (axis.config.number, position)
            return None
        self.clock.wait_until(max(when, t))
        self._update(self.clock.now())
        return None

    def power_cycle(self) -> None:
        """Switch the controller off and on: what ends a ``WP`` that waits for ever.

        As ``RS``: the axes stop where they are, power-on settings (or those saved with
        ``SM``), motors off, the error buffer empty, input received meanwhile lost.
        """
        self.waiting_for = None
        self._cmd_RS("", "", False)

    # -- settings ---------------------------------------------------------------------
    def _setting(self, digits: str, rest: str, query: bool, attribute: str,
                 check: Callable[[AxisState, float], None]) -> str | None:
        axis = self._axis(digits)
        if query:
            return self._out(axis, getattr(axis, attribute))
        value = self._quantity(rest, axis)
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

    def _velocity_command(self, digits, rest, query, attribute):
        """A velocity [units/s]: ``min_velocity <= nn <= VU``, else x01 / x10."""
        def check(axis, value):
            self._check_rate(axis, value, axis.config.min_velocity, axis.max_velocity, 10)
        return self._setting(digits, rest, query, attribute, check)

    def _acceleration_command(self, digits, rest, query, attribute):
        """An acceleration [units/s^2]: ``min_acceleration <= nn <= AU``, else x01 / x11."""
        def check(axis, value):
            self._check_rate(axis, value, axis.config.min_acceleration, axis.max_acceleration, 11)
        return self._setting(digits, rest, query, attribute, check)

    def _retime(self, digits: str, query: bool) -> None:
        """A move in progress follows a changed ``VA``, ``AC`` or ``AG`` from where it is
        (the ESP300 takes them during a motion; :func:`profile_from_state`); a home search
        (its own velocity ``OH``), a jog and a move a limit fault stops keep theirs."""
        axis = self._axis(digits)
        t = self.clock.now()
        if query or not axis.moving(t) or axis.profile is not axis.retimable:
            return
        axis.profile = axis.retimable = profile_from_state(
            t, axis.position(t), axis.profile.velocity(t), axis.target(), axis.velocity, axis.acceleration,
            axis.deceleration)

    def _cmd_VA(self, digits, rest, query):
        """Velocity of moves [units/s], at most ``VU``; a move in progress follows it."""
        reply = self._velocity_command(digits, rest, query, "velocity")
        self._retime(digits, query)
        return reply

    def _cmd_OH(self, digits, rest, query):
        """Homing velocity of ``OR`` [units/s], at most ``VU``."""
        return self._velocity_command(digits, rest, query, "homing_velocity")

    def _cmd_OL(self, digits, rest, query):
        """Low homing velocity [units/s] (manual command ``OL``): stored and read back; the
        emulated search runs at ``OH`` all the way."""
        return self._velocity_command(digits, rest, query, "homing_low_velocity")

    def _cmd_AC(self, digits, rest, query):
        """Acceleration of moves [units/s^2], at most ``AU``; a move in progress follows it."""
        reply = self._acceleration_command(digits, rest, query, "acceleration")
        self._retime(digits, query)
        return reply

    def _cmd_AG(self, digits, rest, query):
        """Deceleration of moves and of ``ST`` [units/s^2], at most ``AU``; a move in progress follows it."""
        reply = self._acceleration_command(digits, rest, query, "deceleration")
        self._retime(digits, query)
        return reply

    def _cmd_AE(self, digits, rest, query):
        """E-stop deceleration of ``AB`` [units/s^2], at most ``AU``."""
        return self._acceleration_command(digits, rest, query, "estop_deceleration")

    def _cmd_VU(self, digits, rest, query):
        """Maximum velocity [units/s], up to the stage's own maximum (x10 above, x01 below the
        minimum); velocities above a lowered ``VU`` are lowered to it."""
        def check(axis, value):
            self._check_rate(axis, value, axis.config.min_velocity, axis.config.max_velocity, 10)
        reply = self._setting(digits, rest, query, "max_velocity", check)
        if not query:
            axis = self._axis(digits)
            axis.velocity = min(axis.velocity, axis.max_velocity)
            axis.homing_velocity = min(axis.homing_velocity, axis.max_velocity)
            for mnemonic in ("VB", "JH", "JW"):
                axis.setup[mnemonic] = min(axis.setup[mnemonic], axis.max_velocity)
        return reply

    def _cmd_AU(self, digits, rest, query):
        """Maximum acceleration and deceleration [units/s^2], up to the stage's own maximum (x11
        above); ``AC``, ``AG`` and ``AE`` above a lowered ``AU`` are lowered to it."""
        def check(axis, value):
            self._check_rate(axis, value, axis.config.min_acceleration, axis.config.max_acceleration, 11)
        reply = self._setting(digits, rest, query, "max_acceleration", check)
        if not query:
            axis = self._axis(digits)
            for attribute in ("acceleration", "deceleration", "estop_deceleration"):
                setattr(axis, attribute, min(getattr(axis, attribute), axis.max_acceleration))
        return reply

    def _cmd_SL(self, digits, rest, query):
        def check(axis, value):
            lo, hi = axis.config.hardware_limits
            if not lo <= value - axis.offset <= hi or value > axis.right_limit:
                raise _EspError(100 * axis.config.number + 1)
        return self._setting(digits, rest, query, "left_limit", check)

    def _cmd_SR(self, digits, rest, query):
        def check(axis, value):
            lo, hi = axis.config.hardware_limits
            if not lo <= value - axis.offset <= hi or value < axis.left_limit:
                raise _EspError(100 * axis.config.number + 1)
        return self._setting(digits, rest, query, "right_limit", check)

    def _cmd_SN(self, digits, rest, query):
        """Display units: the angular codes of :data:`ANGULAR_UNITS` (0, 7 to 11), else x01."""
        axis = self._axis(digits)
        if query:
            return str(axis.units)
        value = self._number(rest, axis)
        if not value.is_integer() or int(value) not in ANGULAR_UNITS:
            raise _EspError(100 * axis.config.number + 1)
        axis.units = int(value)
        return None

    def _cmd_SU(self, digits, rest, query):
        """Encoder resolution [units per encoder count] (manual, command ``SU``).

        ``xxSU?`` replies the axis's resolution in its units.  The emulated encoders are
        fixed hardware, so ``xxSUnn`` accepts only the axis's own resolution (a no-op) and
        refuses any other value with x01.
        """
        axis = self._axis(digits)
        if query:
            return self._out(axis, axis.config.resolution)
        value = self._quantity(rest, axis)
        if not math.isclose(value, axis.config.resolution, rel_tol=1e-9):
            raise _EspError(100 * axis.config.number + 1)
        return None

    # -- motor and servo settings (InstrumentKit's setup_axis / read_setup) ---------------
    def _setup_command(self, digits, rest, query, mnemonic):
        """A setting of :data:`SETUP_SETTINGS`: ``xxAAnn`` stores it, ``xxAA?`` reads it back.

        Out of range: x01 (x10 for a velocity above ``VU``); nothing changes.
        """
        axis = self._axis(digits)
        spec = SETUP_SETTINGS[mnemonic]
        if query:
            return self._format_setup(axis, spec, axis.setup[mnemonic])
        value = self._parse_setup(axis, spec, rest)
        n = axis.config.number
        if mnemonic == "TJ" and axis.moving(self.clock.now()):
            raise _EspError(27)  # the trajectory mode cannot change during a motion
        if value > spec.high(axis):
            raise _EspError(100 * n + spec.above_code)
        if not value >= spec.low(axis):
            raise _EspError(100 * n + 1)
        axis.setup[mnemonic] = value
        return None

    def _parse_setup(self, axis: AxisState, spec: SetupSetting, text: str) -> float:
        """The parameter of a setting command, in degrees for a ``"units"`` setting."""
        if spec.kind == "units":
            return self._quantity(text, axis)
        if spec.kind == "hex":
            return self._hex(text, axis)
        value = self._number(text, axis)
        if spec.kind == "integer" and not value.is_integer():
            raise _EspError(100 * axis.config.number + 1)
        return value

    @staticmethod
    def _hex(text: str, axis: AxisState) -> int:
        """A bit field: hexadecimal digits with an optional ``H`` (manual, command ``ZS``, p. 3-169).

        It must begin with a decimal digit (``0F25H``; ``F25H`` is not a command: error 6).
        """
        if text == "":
            raise _EspError(38)
        if not text[0].isdigit():
            raise _EspError(6)
        digits = text[:-1] if text[-1] in "hH" else text
        if not re.fullmatch(r"[0-9A-Fa-f]{1,8}", digits, re.ASCII):
            raise _EspError(100 * axis.config.number + 1)
        return int(digits, 16)

    def _format_setup(self, axis: AxisState, spec: SetupSetting, value: float) -> str:
        if spec.kind == "units":
            return self._out(axis, value)
        if spec.kind == "hex":
            return f"{int(value):X}H"
        if spec.kind == "integer":
            return str(int(value))
        return _fmt(value)

    def _cmd_QR(self, digits, rest, query):
        """Reduce motor torque: ``xxQRtime,percent`` (0 to 60000 ms, 0 to 100 %), else x01.

        ``xxQR?`` replies ``time, percent``.  Stored; the emulated stages hold their
        position whatever the holding current.
        """
        axis = self._axis(digits)
        if query:
            time_ms, percent = axis.torque_reduction
            return f"{time_ms}, {percent}"
        parts = rest.split(",")
        if rest == "" or len(parts) != 2:
            raise _EspError(38)
        values = [self._number(part, axis) for part in parts]
        if not all(v.is_integer() for v in values) or not (0 <= values[0] <= 60000 and 0 <= values[1] <= 100):
            raise _EspError(100 * axis.config.number + 1)
        axis.torque_reduction = (int(values[0]), int(values[1]))
        return None

    def _axis_action(self, digits, rest, query) -> AxisState:
        """The axis of an action command without parameter and without query form (else error 6)."""
        if query or rest:
            raise _EspError(6)
        return self._axis(digits)

    def _cmd_UF(self, digits, rest, query):
        """Update the servo filter with ``KP``, ``KI``, ``KD``, ``KS`` (manual p. 3-93).

        The emulated servo loop follows the profile exactly (within the repeatability), so
        the gains have no effect on the motion.
        """
        self._axis_action(digits, rest, query)
        return None

    def _cmd_QD(self, digits, rest, query):
        """Update the motor driver with ``QI``, ``QV``, ``QS``, ``QR`` (no effect on the motion)."""
        self._axis_action(digits, rest, query)
        return None

    def _cmd_SM(self, digits, rest, query):
        """Save the settings of every axis to non-volatile memory; ``RS`` loads them."""
        if query or rest or digits:
            raise _EspError(6)
        self.saved = {number: axis.saved_settings() for number, axis in self.axes.items()}
        return None

    # -- moves to a limit -------------------------------------------------------------
    def _direction(self, text: str, axis: AxisState) -> float:
        """``+`` or ``-`` (empty: ``+``, the emulator's choice), else x01."""
        if text in ("", "+"):
            return 1.0
        if text == "-":
            return -1.0
        raise _EspError(100 * axis.config.number + 1)

    def _move_to(self, axis: AxisState, target: float, pending_error: int | None) -> None:
        """Start a move of ``axis`` to the controller position ``target`` at ``VA``, with no
        repeatability error (the end is a limit, not a servo target)."""
        t = self.clock.now()
        axis.desired = target
        axis.profile = self._rest_to_rest(axis, t, axis.position(t), target - axis.offset, axis.velocity)
        axis.pending_error = pending_error

    @staticmethod
    def _rest_to_rest(axis: AxisState, t: float, start: float, end: float, velocity: float) -> MotionProfile:
        """A move from rest to rest in the axis's trajectory mode (``TJ``): trapezoidal, or an
        S-curve with the jerk ``JK``."""
        if axis.setup["TJ"] == TRAJECTORY_SCURVE:
            return scurve_profile(t, start, end, velocity, axis.acceleration, axis.deceleration, axis.setup["JK"])
        return trapezoid_profile(t, start, end, velocity, axis.acceleration, axis.deceleration)

    def _cmd_MT(self, digits, rest, query):
        """Move to the hardware travel limit ``+`` or ``-`` at ``VA``, past the software limits.

        The axis stops on the limit switch without an error (that is the command's end).
        ``xxMT?``: ``0`` while the axis moves, ``1`` when it is stopped.
        """
        axis = self._axis(digits)
        if query:
            return "0" if axis.moving(self.clock.now()) else "1"
        direction = self._direction(rest, axis)
        lo, hi = axis.config.hardware_limits
        target = (hi if direction > 0 else lo) + axis.offset
        self._check_move(axis, target, software_limits=False)
        self._move_to(axis, target, None)
        return None

    def _cmd_MV(self, digits, rest, query):
        """Move indefinitely ``+`` or ``-`` at ``VA`` until ``ST``, ``AB`` or ``MF`` (manual p. 3-101).

        An axis that is not stopped runs into its software limit and stops there with
        x06 / x07, queued when it stops.  ``xxMV?``: ``0`` while the axis moves, ``1`` when
        it is stopped.
        """
        axis = self._axis(digits)
        if query:
            return "0" if axis.moving(self.clock.now()) else "1"
        direction = self._direction(rest, axis)
        n = axis.config.number
        limit, code = (axis.right_limit, 6) if direction > 0 else (axis.left_limit, 7)
        if direction * (limit - axis.encoder_reading(self.clock.now())) <= 0:
            raise _EspError(100 * n + code)  # already at (or beyond) that limit
        self._check_move(axis, limit, software_limits=False)
        self._move_to(axis, limit, 100 * n + code)
        return None

    # -- stored programs (manual 3.3, p. 3-3) ---------------------------------------------
    def _program_number(self, digits: str) -> int:
        """The program number ``xx``: 1 to :data:`MAX_PROGRAMS` (37 missing, 7 outside)."""
        if not digits:
            raise _EspError(37)
        number = int(digits)
        if not 1 <= number <= MAX_PROGRAMS:
            raise _EspError(7)
        return number

    def _cmd_EP(self, digits, rest, query):
        """Enter program entry mode for program ``xx``: the following commands are stored,
        unevaluated, up to ``QP``.  Refused with 27 if program ``xx`` exists (erase it with
        ``XX`` first) or inside a running program."""
        if query or rest:
            raise _EspError(6)
        number = self._program_number(digits)
        if self.programs.get(number) or self._running_program:
            raise _EspError(27)
        self.programs[number] = []
        self.recording = number
        return None

    def _cmd_QP(self, digits, rest, query):
        """Quit program entry mode (in program entry mode, see :meth:`_record`); otherwise nothing."""
        if query or rest or digits:
            raise _EspError(6)
        return None

    def _cmd_XX(self, digits, rest, query):
        """Erase program ``xx`` (nothing if it does not exist)."""
        if query or rest:
            raise _EspError(6)
        erased = self.programs.pop(self._program_number(digits), [])
        self._used_program_memory -= sum(_stored_size(command) for command in erased)
        return None

    def _stored(self, digits: str) -> list[str]:
        program = self.programs.get(self._program_number(digits))
        if not program:
            raise _EspError(27)
        return program

    def _cmd_EX(self, digits, rest, query):
        """Execute program ``xx``: its commands run in order, their query replies are sent.

        Refused with 27 if the program is empty or missing, or from inside a program (a
        program cannot start another, so no program runs for ever).  The program runs to
        its end before the next command of the host is read.
        """
        if query or rest:
            raise _EspError(6)
        program = self._stored(digits)
        if self._running_program:
            raise _EspError(27)
        self._running_program = True
        try:
            return self._run_commands(program)
        finally:
            self._running_program = False

    def _cmd_LP(self, digits, rest, query):
        """List program ``xx``: one reply line per stored command (27 if empty or missing)."""
        if query or rest:
            raise _EspError(6)
        return list(self._stored(digits))

"""Geometry of the three-axis rig: axis positions, directions, separation, move planning.

Axes (docs/protocol.md): axis 1 swings the camera beam; its signed angle ``view`` puts the
camera at polar angle ``|view|`` in the swing plane, on azimuth 0 for ``view >= 0`` and
azimuth 180 for ``view < 0``. Axis 2 is the lamp's polar angle ``theta_i`` and axis 3 its
azimuth ``phi_i`` relative to the swing plane. With ``phi_i = 0`` a positive ``view`` is on
the lamp's side of the normal (backward scattering), matching gonio's signed in-plane
viewing angle. All angles in degrees.

These are pure functions on numbers and numpy arrays; :class:`drivers.rig.Rig` uses them
to refuse a geometry before any command is sent. :func:`misaligned_angles` is the geometry
of a rig that is not perfectly aligned (axis zero offsets, a tilted sample): the emulator
uses it to place its lamp and camera, and gonio's fits use the same function for their
alignment parameters (docs/emulator.md, "Systematic errors").
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "AXIS_VIEW",
    "AXIS_THETA_I",
    "AXIS_PHI_I",
    "camera_direction",
    "unit_vector",
    "angular_separation",
    "axis_targets",
    "check_targets",
    "plan_moves",
    "MovePlan",
    "separation_of_axes",
    "misaligned_angles",
    "ALIGNMENT_ERRORS",
    "too_close",
    "travel_refusal",
    "separation_refusal",
]

AXIS_VIEW, AXIS_THETA_I, AXIS_PHI_I = 1, 2, 3
AXES = (AXIS_VIEW, AXIS_THETA_I, AXIS_PHI_I)
#: Extra separation required of targets and intermediate target combinations [deg], so
#: that rounding in the controller's own check cannot refuse a planned move.
SEPARATION_MARGIN = 0.01

AXIS_NAMES = {AXIS_VIEW: "view (camera swing)", AXIS_THETA_I: "theta_i", AXIS_PHI_I: "phi_i"}

def camera_direction(view):
    """Camera polar angle and azimuth ``(theta_r, phi_r)`` [deg] of the signed swing angle.

    Examples
    --------
    >>> camera_direction(-30.0)
    (30.0, 180.0)
    """
    view = np.asarray(view, dtype=float)
    theta_r = np.abs(view)
    phi_r = np.where(view >= 0, 0.0, 180.0)
    if theta_r.ndim == 0:
        return float(theta_r), float(phi_r)
    return theta_r, phi_r


def unit_vector(theta, phi) -> np.ndarray:
    """Unit direction of polar angle ``theta`` and azimuth ``phi`` [deg]; last axis xyz."""
    t, p = np.radians(theta), np.radians(phi)
    st = np.sin(t)
    return np.stack(np.broadcast_arrays(st * np.cos(p), st * np.sin(p), np.cos(t)), axis=-1)


def angular_separation(theta_i, phi_i, theta_r, phi_r):
    """Angle between the lamp and camera directions [deg].

    Computed as ``atan2(|a x b|, a . b)``, accurate also for nearly parallel directions
    (where ``arccos`` of the dot product loses precision).

    Examples
    --------
    >>> round(float(angular_separation(30, 0, 30, 0)), 9)
    0.0
    >>> round(float(angular_separation(30, 0, 30, 180)), 9)
    60.0
    """
    a = unit_vector(theta_i, phi_i)
    b = unit_vector(theta_r, phi_r)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


def separation_of_axes(positions: Mapping[int, float] | np.ndarray):
    """Separation [deg] for axis positions ``{1: view, 2: theta_i, 3: phi_i}`` (or an
    array whose last axis holds the three positions)."""
    if isinstance(positions, Mapping):
        view, theta_i, phi_i = (positions[a] for a in AXES)
    else:
        arr = np.asarray(positions, dtype=float)
        view, theta_i, phi_i = arr[..., 0], arr[..., 1], arr[..., 2]
    theta_r, phi_r = camera_direction(view)
    return angular_separation(theta_i, phi_i, theta_r, phi_r)


def axis_targets(theta_i: float, phi_i: float, view: float) -> dict[int, float]:
    """Axis positions of a measurement geometry: ``{1: view, 2: theta_i, 3: phi_i}`` [deg]."""
    return {AXIS_VIEW: float(view), AXIS_THETA_I: float(theta_i), AXIS_PHI_I: float(phi_i)}


def too_close(separation, min_separation: float):
    """Whether camera and lamp ``separation`` [deg] apart (scalar or array) are refused.

    Closer than ``min_separation`` plus :data:`SEPARATION_MARGIN` (0.01 deg): a geometry
    exactly at the minimum is refused, since the controller's own floating-point check may
    go either way there. The one rule of the driver's checks (:func:`check_targets`), its
    move plans (:func:`plan_moves`) and a protocol's plan (``gonio.protocols``), so that
    the plan refuses what the rig refuses.

    >>> bool(too_close(5.0, 5.0)), bool(too_close(5.02, 5.0))
    (True, False)
    """
    return np.asarray(separation, dtype=float) < min_separation + SEPARATION_MARGIN


def travel_refusal(axis: int, value: float, limits: tuple[float, float]) -> str | None:
    """Why ``value`` [deg] is not a target of stage ``axis`` with travel ``limits``, or None.

    >>> travel_refusal(1, 95.0, (-90.0, 90.0))
    'view (camera swing)=95 deg is outside the travel limits of axis 1: [-90, 90] deg'
    """
    if not math.isfinite(value):
        return f"{AXIS_NAMES[axis]}={value!r} is not a finite angle"
    low, high = limits
    if not low <= value <= high:
        return f"{AXIS_NAMES[axis]}={value:g} deg is outside the travel limits of axis {axis}: [{low:g}, {high:g}] deg"
    return None


def separation_refusal(separation: float, min_separation: float) -> str:
    """The reason given for camera and lamp ``separation`` [deg] apart that are too close.

    >>> separation_refusal(5.0, 5.0)
    'camera and lamp only 5.00 deg apart (the rig keeps them more than its minimum separation, 5 deg, apart)'
    """
    return (f"camera and lamp only {separation:.2f} deg apart (the rig keeps them more than its "
            f"minimum separation, {min_separation:g} deg, apart)")


def check_targets(
    targets: Mapping[int, float],
    limits: Mapping[int, tuple[float, float]],
    min_separation: float,
) -> str | None:
    """Reason why axis targets are not allowed, or ``None``.

    Checks every target is finite and within its travel limits and the lamp/camera
    separation at the target is not :func:`too_close` to ``min_separation`` [deg].
    """
    for axis in AXES:
        reason = travel_refusal(axis, float(targets[axis]), limits[axis])
        if reason:
            return reason
    separation = float(separation_of_axes(targets))
    if too_close(separation, min_separation):
        return separation_refusal(separation, min_separation)
    return None


@dataclass(frozen=True)
class MovePlan:
    """Stages of a move; within a stage the axis commands are sent in the listed order.

    The controller checks the camera/lamp separation at the *end point* of each move
    command, using the targets of all axes (docs/protocol.md, error x29). Every prefix
    of a stage therefore has to leave a safe combination of targets; the axes of a stage
    then move together, and the next stage starts when they have stopped.

    Attributes
    ----------
    stages : tuple of tuple of (int, float)
        ``((axis, target), ...)`` per stage [deg].
    """

    stages: tuple[tuple[tuple[int, float], ...], ...]


def _order_ok(start: Mapping[int, float], order: Sequence[int], end: Mapping[int, float],
              min_separation: float) -> bool:
    targets = dict(start)
    for axis in order[:-1]:
        targets[axis] = end[axis]
        if too_close(separation_of_axes(targets), min_separation):
            return False
    return True


def _one_stage(start, end, min_separation):
    moving = [a for a in AXES if abs(end[a] - start[a]) > 1e-9]
    for order in itertools.permutations(moving):
        if _order_ok(start, order, end, min_separation):
            return tuple((a, float(end[a])) for a in order)
    return None


def plan_moves(
    start: Mapping[int, float],
    end: Mapping[int, float],
    min_separation: float,
    limits: Mapping[int, tuple[float, float]] | None = None,
) -> MovePlan | None:
    """Plan the move commands from ``start`` to ``end`` axis targets, or ``None``.

    One stage when some order of the axis commands keeps every intermediate combination
    of targets at least ``min_separation`` [deg] apart; otherwise two stages through a
    waypoint that differs from ``start`` in one axis (searched on a 15-degree grid inside
    ``limits``, the shortest detour first). ``end`` itself must already be allowed (see :func:`check_targets`).

    Examples
    --------
    >>> plan = plan_moves({1: 30, 2: 50, 3: 0}, {1: 50, 2: 30, 3: 0}, 5.0)
    >>> len(plan.stages)    # camera and lamp swap sides of each other: via a waypoint
    2
    """
    stage = _one_stage(start, end, min_separation)
    if stage is not None:
        return MovePlan((stage,) if stage else ())
    limits = limits or {AXIS_VIEW: (-90.0, 90.0), AXIS_THETA_I: (0.0, 90.0), AXIS_PHI_I: (-180.0, 180.0)}
    best, best_cost = None, np.inf
    for axis in (AXIS_PHI_I, AXIS_THETA_I, AXIS_VIEW):
        low, high = limits[axis]
        for value in np.arange(np.ceil(low / 15.0) * 15.0, high + 1e-9, 15.0):
            cost = abs(float(value) - start[axis])
            if cost >= best_cost:
                continue
            waypoint = dict(start)
            waypoint[axis] = float(value)
            if too_close(separation_of_axes(waypoint), min_separation):
                continue
            first = _one_stage(start, waypoint, min_separation)
            second = _one_stage(waypoint, end, min_separation)
            if first is not None and second is not None:
                best, best_cost = MovePlan(tuple(s for s in (first, second) if s)), cost
    if best is not None:
        return best
    return None


#: The alignment errors of :func:`misaligned_angles`, in its keyword order [deg].
ALIGNMENT_ERRORS = ("view_offset", "theta_i_offset", "phi_i_offset", "tilt_x", "tilt_y")


def _direction_angles(x, y, z):
    """Polar angle and azimuth [deg] of (not necessarily unit) direction components."""
    return np.degrees(np.arctan2(np.hypot(x, y), z)), np.degrees(np.arctan2(y, x))


def misaligned_angles(theta_i, phi_i, theta_r, phi_r, *, view_offset=0.0, theta_i_offset=0.0,
                      phi_i_offset=0.0, tilt_x=0.0, tilt_y=0.0):
    """True lamp and camera directions in the sample's frame of a misaligned rig [deg].

    The rig reads back the geometry ``(theta_i, phi_i, theta_r, phi_r)`` (lamp polar
    angle and azimuth from axes 2 and 3, camera direction from the swing of axis 1); the
    directions the sample actually sees differ by the rig's alignment errors:

    - **zero offsets** of the axes: the true angle of an axis is its readback plus its
      offset. The camera is swung about the swing axis (y) by ``view_offset``, so a camera
      in the swing plane sits at the signed view ``view + view_offset``; the lamp is at polar
      angle ``theta_i + theta_i_offset`` and azimuth ``phi_i + phi_i_offset``.
    - **sample tilt**: the sample's normal is tipped by ``tilt_x`` toward +x (within the
      swing plane, toward the camera at positive views) and by ``tilt_y`` toward +y (along
      the swing axis), i.e. the sample frame is the lab frame rotated by
      ``R = R_y(tilt_x) R_x(-tilt_y)``, whose normal is
      ``(sin tilt_x cos tilt_y, sin tilt_y, cos tilt_x cos tilt_y)``. Directions are expressed
      in the sample frame as ``R^T d``.

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        The geometry the rig read back [deg] (``theta_r = |view|``, ``phi_r`` 0 for
        ``view >= 0`` and 180 otherwise on this rig; any direction is accepted).
    view_offset, theta_i_offset, phi_i_offset : array_like
        Zero offsets of axes 1, 2 and 3 [deg]: true angle = readback + offset.
    tilt_x, tilt_y : array_like
        Tilt of the sample's normal toward +x and +y [deg].

    Returns
    -------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        The true directions in the sample's frame [deg], broadcast over every argument:
        polar angles in [0, 180] (above 90: the direction is behind the sample), azimuths
        in (-180, 180].

    Notes
    -----
    A lamp pushed through the normal by its offset (``theta_i + theta_i_offset < 0``)
    comes out at the opposite azimuth, as the vector form gives it. With every error 0 the
    result is the input to rounding (azimuths wrapped into (-180, 180]).

    References
    ----------
    E. Molloy, P. Saunders, A. Koo, "Effects of rotation errors on goniometric
    measurements", Metrologia 59(2), 2022 (axis offsets and sample alignment as error
    sources of a goniometer).

    Examples
    --------
    >>> ti, pi, tr, pr = misaligned_angles(30.0, 0.0, 20.0, 0.0, view_offset=0.5, theta_i_offset=-0.2)
    >>> [round(float(a), 9) for a in (ti, pi, tr, pr)]
    [29.8, 0.0, 20.5, 0.0]
    >>> ti, _, tr, _ = misaligned_angles(30.0, 0.0, 20.0, 180.0, tilt_x=1.0)
    >>> round(float(ti), 9), round(float(tr), 9)      # the normal tips toward the lamp
    (29.0, 21.0)
    """
    rad = np.pi / 180.0
    t_lamp = (np.asarray(theta_i, float) + theta_i_offset) * rad
    p_lamp = (np.asarray(phi_i, float) + phi_i_offset) * rad
    lamp = (np.sin(t_lamp) * np.cos(p_lamp), np.sin(t_lamp) * np.sin(p_lamp), np.cos(t_lamp))
    t_cam, p_cam = np.asarray(theta_r, float) * rad, np.asarray(phi_r, float) * rad
    swing = np.asarray(view_offset, float) * rad
    cx, cy, cz = np.sin(t_cam) * np.cos(p_cam), np.sin(t_cam) * np.sin(p_cam), np.cos(t_cam)
    camera = (cx * np.cos(swing) + cz * np.sin(swing), cy, cz * np.cos(swing) - cx * np.sin(swing))
    a, b = np.asarray(tilt_x, float) * rad, np.asarray(tilt_y, float) * rad
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)

    def to_sample(x, y, z):
        # R^T (x, y, z) with R = R_y(a) R_x(-b): first R_y(-a), then R_x(b)
        x1, z1 = x * ca - z * sa, x * sa + z * ca
        return x1, y * cb - z1 * sb, y * sb + z1 * cb

    ti, pi_ = _direction_angles(*to_sample(*lamp))
    tr, pr = _direction_angles(*to_sample(*camera))
    return np.broadcast_arrays(ti, pi_, tr, pr)

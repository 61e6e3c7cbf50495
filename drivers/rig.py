"""The gonioreflectometer as one object: stage, camera and lamp behind a small interface.

:class:`Rig` is what acquisition code uses, so that the same measurement plan runs on the
emulator and on a real rig speaking the protocols of docs/protocol.md::

    with Rig.open(stage="/dev/ttyUSB0", camera="/dev/ttyUSB1", lamp="/dev/ttyUSB2") as rig:
        rig.lamp_on(120.0)
        rig.wait_lamp_stable()
        rig.move_to(theta_i=30.0, phi_i=0.0, view=-20.0)
        record = rig.measure()            # Measurement: radiance, ROI statistics, ...

Geometry. ``view`` is the signed camera swing angle (axis 1): the camera is at polar angle
``|view|`` on azimuth 0 (``view >= 0``, the lamp's side when ``phi_i = 0``) or 180. The
lamp is at ``(theta_i, phi_i)`` (axes 2, 3). A geometry is refused with
:class:`~drivers.errors.GeometryError` *before anything is sent* when a target is outside
the travel limits read from the controller (``SL?``/``SR?``) or the camera would come
closer than ``min_separation`` to the lamp. The controller checks the separation at the
end point of every move command (protocol: error x29), so the rig orders the axis
commands such that every intermediate combination of targets is allowed too, detouring
through a waypoint when no order works.

Radiance. :meth:`Rig.measure` returns the dark-subtracted ROI mean per unit exposure time
and unit analog gain, ``(mean - dark) / (t_exp * gain)`` [DN/s per ROI pixel at unit
gain], times :attr:`Rig.radiance_scale` (default 1). Because every pixel sees the same
solid angle of the sample's radiance, this number is proportional to the sample radiance
towards the camera and independent of the viewing angle (the foreshortened sample fills
more of each pixel); it is a *relative* radiance. An absolute scale comes later from a
reference standard: measure it, then set ``radiance_scale``.

ROI. The region of interest is computed from the optics reported by ``SENS:INFO?``: a
window of ``roi_fraction`` times the sample side (default half, i.e. the central 1 x 1 inch
of the 2 x 2 inch sample), foreshortened along the swing-plane image axis by
``cos(theta_r)``, so that it covers the same sample area at every camera angle. The
far-field magnification ``m = f / D`` is used (docs/protocol.md); perspective across the
sample (D = 1.83 m against a 51 mm sample) is neglected. The ROI is checked to lie inside
the sample's image with a margin of ``roi_margin_px`` pixels.

Exposure. With ``exposure="auto"`` (default) the exposure is chosen on a ladder of
12 steps per decade so that the raw ROI mean lies between ``exposure_window`` fractions of
the ADC maximum, aiming at ``target_fraction``, with no saturated pixel in the ROI. When
even the longest allowed exposure gives a weak signal, that frame is returned (a weak
signal is a measurement; acquisition flags it ``low_signal``); only a point at which every
frame saturates raises :class:`~drivers.errors.ExposureError`.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from typing import Mapping

import numpy as np

from .acceptance import GeometryRule
from .camera import Camera, Roi, RoiStats, SensorInfo
from .errors import (
    DriverError,
    ExposureError,
    GeometryError,
    LampError,
    MotionTimeout,
    PositionError,
    ProtocolError,
    StageError,
    TransportError,
)
from .esp300 import ESP300
from .lamp import Lamp
from .measurement import DarkLevel, Measurement
from .monitor import MonitorDark, characterise
from .rig_checks import exposure_ladder_floor, exposure_window, position_problem, steadiness
from .roi import SAMPLE_SIZE_MM, roi_for_view, roi_problem, sample_image_size
from .rig_geometry import (
    AXES,
    AXIS_PHI_I,
    AXIS_THETA_I,
    AXIS_VIEW,
    axis_targets,
    camera_direction,
    plan_moves,
)

__all__ = ["Rig", "Measurement", "DarkLevel", "roi_for_view", "roi_problem", "sample_image_size", "exposure_ladder_floor"]

_log = logging.getLogger(__name__)

#: Home positions of the axes (docs/protocol.md) [deg].
HOME = {AXIS_VIEW: 0.0, AXIS_THETA_I: 45.0, AXIS_PHI_I: 0.0}


class Rig:
    """Stage, camera and lamp of the gonioreflectometer.

    Use :meth:`open` to connect by port paths or pyserial URLs; the constructor takes
    already opened drivers.

    Parameters
    ----------
    stage : ESP300
    camera : Camera
    lamp : Lamp
    min_separation : float
        Smallest allowed angle between camera and lamp directions [deg]; must match the
        controller's interlock (default 5).
    gain : float
        Analog gain factor used for measurements [-].
    roi_fraction : float
        Side of the radiance window as a fraction of the sample side [-].
    sample_size_mm : float
        Side of the square sample [mm].
    roi_margin_px : float
        Margin kept between the ROI and the edge of the sample's image [pixel].
    exposure_limits : (float, float)
        Range of automatic exposures [s]. The default ends at 10 s, where the hot
        pixels of the rig's CCD (2000 e-/s) are still below full well.
    target_fraction : float
        Aim of the automatic exposure for the raw ROI mean, as a fraction of the ADC
        maximum [-].
    exposure_window : (float, float)
        Raw ROI means accepted by the automatic exposure, as fractions of the ADC maximum.
    radiance_scale : float
        Factor from DN/s per pixel at unit gain to the reported radiance unit.
    home : mapping
        Home positions of the axes [deg] (docs/protocol.md).
    position_tolerance : float
        Largest accepted difference between an axis's encoder readback and its target
        after a move [deg]. The default 0.01 deg is five times the emulated stage's
        repeatability (0.002 deg, 1 sigma) and ten encoder steps.
    move_retries : int
        Further attempts of a move whose readback, limit stop or garbled reply left the
        geometry unconfirmed; the stage state is re-read from the controller before each.

    Notes
    -----
    Every move is verified: the encoder readback of all three axes must agree with the
    targets within ``position_tolerance`` (read twice before it counts as a mismatch, so
    a garbled reply that still parses as a number is not taken for the position). A
    mismatch, a stage error (a tripped limit switch), a reply that cannot be parsed or a
    timeout re-reads the controller's targets (``DP?``) and retries the move; when the
    retries are used up :class:`~drivers.errors.PositionError` says why, and nothing is
    measured at a geometry the rig did not confirm.
    """

    def __init__(
        self,
        stage: ESP300,
        camera: Camera,
        lamp: Lamp,
        *,
        min_separation: float = 5.0,
        gain: float = 1.0,
        roi_fraction: float = 0.5,
        sample_size_mm: float = SAMPLE_SIZE_MM,
        roi_margin_px: float = 2.0,
        exposure_limits: tuple[float, float] = (1e-4, 10.0),
        target_fraction: float = 0.45,
        exposure_window: tuple[float, float] = (0.3, 0.75),
        radiance_scale: float = 1.0,
        home: Mapping[int, float] = HOME,
        position_tolerance: float = 0.01,
        move_retries: int = 2,
    ) -> None:
        if not min_separation >= 0:
            raise ValueError(f"min_separation={min_separation!r} deg must be >= 0")
        low, high = exposure_window
        if not 0 < low < target_fraction < high < 1:
            raise ValueError(
                f"exposure_window={exposure_window!r} and target_fraction={target_fraction!r} "
                "must satisfy 0 < low < target < high < 1"
            )
        if not 0 < exposure_limits[0] < exposure_limits[1]:
            raise ValueError(f"exposure_limits={exposure_limits!r} must be 0 < min < max [s]")
        if not position_tolerance > 0:
            raise ValueError(f"position_tolerance={position_tolerance!r} deg must be > 0")
        if int(move_retries) < 0:
            raise ValueError(f"move_retries={move_retries!r} must be >= 0")
        self.stage = stage
        self.camera = camera
        self.lamp = lamp
        self.min_separation = float(min_separation)
        self.gain = float(gain)
        self.roi_fraction = float(roi_fraction)
        self.sample_size_mm = float(sample_size_mm)
        self.roi_margin_px = float(roi_margin_px)
        self.exposure_limits = (float(exposure_limits[0]), float(exposure_limits[1]))
        self.target_fraction = float(target_fraction)
        self.exposure_window = (float(low), float(high))
        self.radiance_scale = float(radiance_scale)
        self.home_position = {int(a): float(v) for a, v in home.items()}
        self.limits: dict[int, tuple[float, float]] = {}
        self.info: SensorInfo | None = None
        self._targets: dict[int, float] | None = None
        self._position: dict[int, float] = {}
        self._view: float | None = None
        self._roi: Roi | None = None
        self._exposure: float | None = None
        self._darks: dict[tuple, DarkLevel] = {}
        self._dark_model: tuple[float, float, float] | None = None  # gain, offset, rate
        self._velocity: dict[int, float] = {}
        self._acceleration: dict[int, float] = {}
        self.position_tolerance = float(position_tolerance)
        self.move_retries = int(move_retries)
        self.encoder_resolution: dict[int, float] = {}
        #: Whether the camera has the lamp monitor option (``*OPT?`` lists ``MON``).
        self.has_monitor = False
        #: Dark characterisation of the lamp monitor (:meth:`measure_monitor_dark`).
        self.monitor_dark: MonitorDark | None = None
        self._last_monitor = math.nan
        #: The instruments' clock [s] when they offer one (the emulator's simulated clock,
        #: ``SIM:TIME?``), else None: acquisition then records wall-clock time.
        self.instrument_clock = None
        #: Identity strings of the instruments (read by :meth:`initialize`).
        self.identities: dict[str, str] = {}

    # -- life cycle -----------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        stage: str,
        camera: str,
        lamp: str,
        *,
        timeout: float = 2.0,
        retries: int = 1,
        initialize: bool = True,
        **options,
    ) -> "Rig":
        """Connect to the three instruments by port path or pyserial URL.

        Parameters
        ----------
        stage, camera, lamp : str
            Port paths or URLs (``/dev/ttyUSB0``, ``gonio-sim://stage?rig=lab``,
            ``socket://127.0.0.1:5000`` ...).
        timeout : float
            Reply timeout of each line [s].
        retries : int
            Retries of a query after a transient failure.
        initialize : bool
            Run :meth:`initialize` (identity check, clear errors, motors on, limits).
        **options
            Passed to the constructor (``min_separation``, ``gain``, ...).
        """
        opened = []
        try:
            s = ESP300.open(stage, timeout=timeout, retries=retries)
            opened.append(s)
            c = Camera.open(camera, timeout=timeout, retries=retries)
            opened.append(c)
            l = Lamp.open(lamp, timeout=timeout, retries=retries)
            opened.append(l)
            rig = cls(s, c, l, **options)
            if initialize:
                rig.initialize()
            return rig
        except BaseException:
            for driver in opened:
                driver.close()
            raise

    def initialize(self) -> dict[str, str]:
        """Check identities, clear stale errors, switch the motors on, read limits and optics.

        Returns
        -------
        dict
            Identity strings of ``stage``, ``camera`` and ``lamp``.
        """
        identities = {
            "stage": self.stage.identity(),
            "camera": self.camera.identity(),
            "lamp": self.lamp.identity(),
        }
        stale = {
            "stage": self.stage.errors(),
            "camera": self.camera.errors(),
            "lamp": self.lamp.errors(),
        }
        for device, errors in stale.items():
            for error in errors:
                _log.warning("%s: stale error at connection: %s", device, error)
        for axis in AXES:
            unit = self.stage.units(axis)
            if unit != "degree":
                raise DriverError(f"stage axis {axis} is in {unit!r}; the rig needs degrees (SN7)")
            self.stage.motor_on(axis)
            self.limits[axis] = self.stage.travel_limits(axis)
            self._velocity[axis] = self.stage.velocity(axis)
            self._acceleration[axis] = min(self.stage.acceleration(axis), self.stage.deceleration(axis))
            self.encoder_resolution[axis] = self.stage.encoder_resolution(axis)
        self._targets = {a: self.stage.desired_position(a) for a in AXES}
        self.info = self.camera.sensor_info()
        self.has_monitor = "MON" in self.camera.options()
        self.instrument_clock = self.camera.simulated_time if self.camera.simulated_time() is not None else None
        self.identities = dict(identities)
        self.camera.set_gain(self.gain)
        self.camera.open_shutter()
        self._exposure = self.camera.exposure()
        return identities

    def close(self) -> None:
        """Close the three serial lines (the instruments keep their state)."""
        for driver in (self.stage, self.camera, self.lamp):
            driver.close()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- time and lamp --------------------------------------------------------------------
    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass in the instruments' time (the controller's ``WS`` delay)."""
        self.stage.wait(seconds)

    def lamp_on(self, voltage: float) -> None:
        """Set the lamp voltage [V] and switch the output on; raise if the lamp is faulty."""
        self.lamp.set_voltage(voltage)
        self.lamp.output_on()
        self.lamp.check_lamp()

    def lamp_off(self) -> None:
        """Switch the lamp output off."""
        self.lamp.output_off()

    def lamp_is_on(self) -> bool:
        """Whether the lamp supply's output is on (``OUTP?``)."""
        return self.lamp.output_is_on()

    def wait_lamp_stable(
        self, settle_time: float = 600.0, *, readings: int = 10, interval: float = 30.0, limit_sigma: float = 6.0,
        min_change: float = 1e-3,
    ) -> dict[str, float]:
        """Wait for the lamp to warm up, then check that it no longer changes.

        The lamp output settles with the filament's thermal time constant and then the
        bulb's warm-up (120 s for the rig's lamp, docs/protocol.md); the default wait of
        600 s leaves less than 0.02 % of a 2 % warm-up deficit. Afterwards ``readings``
        supply-current readings (and, with a lamp monitor, as many monitor readings of
        10 ms exposures) are taken, then again after ``interval`` seconds; the change of
        their means must stay within ``limit_sigma`` standard errors estimated from the
        readings' own scatter (:func:`~drivers.rig_checks.steadiness`), so the tolerance
        follows the read-back noise of the instrument at hand. A change below
        ``min_change`` (relative, over ``interval``) is accepted however quiet the readings:
        slow drift of that size is what the monitor or the lamp checks correct, while a lamp
        in its warm-up changes several times faster (10 s after switch-on the rig's lamp
        rises by 4.5e-3 in 30 s).

        The current reveals a cold filament (the inrush of the first second) and an
        unsteady supply; only the monitor sees the bulb's slow warm-up.

        Returns
        -------
        dict
            ``voltage`` [V] and ``current`` [A] after the wait, the relative changes
            ``current_change`` and (with a monitor) ``monitor_change`` [-].

        Raises
        ------
        LampError
            If the output is off, the lamp reports a fault, or a reading changed by more
            than its noise allows.
        """
        if not self.lamp.output_is_on():
            raise LampError(0, "lamp output is off; call lamp_on() first", "OUTP?")
        self.wait(settle_time)
        first = self._lamp_readings(readings)
        self.wait(interval)
        second = self._lamp_readings(readings)
        self.lamp.check_lamp()
        result = {"voltage": self.lamp.measured_voltage(), "current": float(np.mean(second["current"]))}
        for name, values in first.items():
            change, tolerance = steadiness(values, second[name], limit_sigma)
            tolerance = max(tolerance, min_change)
            result[f"{name}_change"] = change
            if not abs(change) <= tolerance:
                raise LampError(
                    0, f"lamp not steady after {settle_time:g} s: the {name} changed by {change:.2e} (relative) "
                       f"in {interval:g} s, more than {limit_sigma:g} standard errors of its readings and "
                       f"{min_change:g} ({tolerance:.2e})",
                    "MEAS:CURR?" if name == "current" else "MON?",
                )
        return result

    def _lamp_readings(self, count: int) -> dict[str, list[float]]:
        """``count`` supply-current readings [A] and, with a monitor, 10 ms monitor readings [V]."""
        out = {"current": [self.lamp.measured_current() for _ in range(count)]}
        if self.has_monitor:
            saved = self._exposure
            out["monitor"] = []
            for _ in range(count):
                self._set_exposure(0.01)
                self.camera.acquire()
                out["monitor"].append(self.camera.monitor())
            if saved is not None:
                self._set_exposure(saved)
        return out

    def measure_monitor_dark(self, exposures: tuple[float, float] = (0.01, 0.1), readings: int = 16) -> MonitorDark:
        """Measure the lamp monitor's offset and noise with the lamp off.

        Takes ``readings`` exposures with the shutter closed at each of the two
        ``exposures`` [s] and reads the monitor after each (:func:`drivers.monitor.characterise`).
        The result is kept in :attr:`monitor_dark`.

        Raises
        ------
        DriverError
            If the rig has no lamp monitor.
        LampError
            If the lamp output is on (switch it off and let the filament cool first).
        """
        if not self.has_monitor:
            raise DriverError("the camera reports no lamp monitor option (*OPT? has no MON)")
        if self.lamp.output_is_on():
            raise LampError(0, "the monitor's dark reading needs the lamp off; call lamp_off() first", "OUTP?")
        saved = self._exposure
        values: dict[float, list[float]] = {}
        self.camera.close_shutter()
        try:
            for t in exposures:
                self._set_exposure(float(t))
                values[float(t)] = []
                for _ in range(readings):
                    self.camera.acquire()
                    values[float(t)].append(self.camera.monitor())
        finally:
            self.camera.open_shutter()
            if saved is not None:
                self._set_exposure(saved)
        self.monitor_dark = characterise(values)
        return self.monitor_dark

    def set_motion(self, velocity: float | None = None, acceleration: float | None = None) -> None:
        """Program every stage axis with one velocity [deg/s] and/or acceleration [deg/s^2].

        The acceleration is programmed as both the acceleration (``AC``) and the
        deceleration (``AG``) of the moves. ``None`` leaves the controller's setting. The
        controller refuses values above an axis's maximum (``x10``/``x11``), which raises
        :class:`StageError`.
        """
        for axis in AXES:
            if velocity is not None:
                self.stage.set_velocity(axis, float(velocity))
                self._velocity[axis] = self.stage.velocity(axis)
            if acceleration is not None:
                self.stage.set_acceleration(axis, float(acceleration))
                self.stage.set_deceleration(axis, float(acceleration))
                self._acceleration[axis] = min(self.stage.acceleration(axis), self.stage.deceleration(axis))

    # -- geometry -------------------------------------------------------------------------
    def _require_initialized(self) -> None:
        if not self.limits or self.info is None:
            raise DriverError("the rig is not initialized; call initialize() (Rig.open does)")

    @property
    def geometry_rule(self) -> GeometryRule:
        """The rule deciding which geometries this rig measures (:mod:`drivers.acceptance`):
        the controller's travel limits, the separation and the camera's reported optics."""
        self._require_initialized()
        return GeometryRule(self.limits[AXIS_VIEW], self.limits[AXIS_THETA_I], self.limits[AXIS_PHI_I],
                            self.min_separation, self.info, self.roi_fraction, self.sample_size_mm,
                            self.roi_margin_px)

    def check_geometry(self, theta_i: float, phi_i: float, view: float) -> str | None:
        """Why the geometry cannot be measured (travel limits, separation, no radiance window
        on the sample), or ``None``; :meth:`GeometryRule.refusal` of :attr:`geometry_rule`.

        Nothing is sent to the instruments.
        """
        return self.geometry_rule.refusal(theta_i, phi_i, view)

    def _move_timeout(self, start: Mapping[int, float], end: Mapping[int, float]) -> float:
        """Time the slowest axis needs for its trapezoidal move, + the line timeout [s]."""
        longest = 0.0
        for axis, target in end.items():
            d = abs(target - start[axis])
            v, a = self._velocity.get(axis, 1.0), self._acceleration.get(axis, 1.0)
            t = d / v + v / a if d >= v * v / a else 2 * math.sqrt(d / a)
            longest = max(longest, t)
        return 1.2 * longest + self.stage.line.timeout + 1.0

    def move_to(self, theta_i: float, phi_i: float, view: float) -> dict[int, float]:
        """Move lamp and camera to a measurement geometry, wait until stopped, verify.

        The geometry is checked first (:meth:`check_geometry`); a refused geometry raises
        :class:`GeometryError` and nothing is sent. After the move the encoder readback
        must confirm every target within :attr:`position_tolerance`; otherwise the stage
        state is re-read and the move retried (see the class notes).

        Returns
        -------
        dict
            Encoder readback ``{1: view, 2: theta_i, 3: phi_i}`` [deg].

        Raises
        ------
        GeometryError
            Outside the travel limits, too close to the lamp, or no ROI on the sample.
        PositionError
            If no attempt reached and confirmed the geometry (limit stops, stage errors,
            garbled or missing replies, readback off target).
        """
        reason = self.check_geometry(theta_i, phi_i, view)
        if reason:
            raise GeometryError(reason)
        end = axis_targets(theta_i, phi_i, view)
        failures: list[str] = []
        for attempt in range(1 + self.move_retries):
            try:
                self._run_moves(end)
                position = self._confirmed_position(end)
            except (StageError, ProtocolError, TransportError, MotionTimeout, PositionError) as error:
                failures.append(f"attempt {attempt + 1}: {type(error).__name__}: {error}")
                _log.warning("stage: move to %s not confirmed (%s); re-reading the controller", end, error)
                if not self._resynchronise():
                    failures.append("the controller does not answer; not retrying")
                    break
                continue
            self._targets = dict(end)
            self._position = position
            self._set_view(view)
            return dict(position)
        raise PositionError(
            f"the stage did not reach theta_i={theta_i:g}, phi_i={phi_i:g}, view={view:g} deg "
            f"in {1 + self.move_retries} attempt(s): " + "; ".join(failures)
        )

    def _run_moves(self, end: Mapping[int, float]) -> None:
        """Send the axis commands from the known targets to ``end`` and wait for each stage."""
        start = dict(self._targets) if self._targets else {a: self.stage.desired_position(a) for a in AXES}
        plan = plan_moves(start, end, self.min_separation, self.limits)
        if plan is None:
            raise GeometryError(
                f"no sequence of axis moves reaches {dict(end)} from {start} without violating "
                f"the {self.min_separation:g}-deg separation"
            )
        self._targets = None  # unknown until the moves are confirmed
        current = dict(start)
        for stage in plan.stages:
            self.stage.send(";".join(f"{axis}PA{target:.5f}" for axis, target in stage))
            goal = dict(current)
            goal.update(dict(stage))
            self.stage.wait(0.0, timeout=self._move_timeout(current, goal))
            current = goal

    def _confirmed_position(self, targets: Mapping[int, float]) -> dict[int, float]:
        """Encoder readback agreeing with ``targets``, read twice before a mismatch counts."""
        problem = None
        for _ in range(2):
            position = self.stage.positions(AXES)
            problem = position_problem(position, targets, self.position_tolerance)
            if problem is None:
                return position
        raise PositionError(problem)

    def _resynchronise(self) -> bool:
        """After a failed move: drop stale input, drain errors, wait, re-read the targets.

        Returns False when the controller does not answer at all (a dead line: retrying is
        pointless); any other failure is logged and left to the next attempt.
        """
        try:
            self.stage.line.discard_input()
            for entry in self.stage.errors():
                _log.warning("stage: error %d after a failed move: %s", entry.code, entry.message)
        except TransportError as error:
            _log.warning("stage: no answer after a failed move: %s", error)
            self._targets = None
            return False
        except DriverError as error:
            _log.warning("stage: could not read its errors: %s", error)
        try:
            self.stage.wait(0.0, timeout=self._move_timeout({a: 0.0 for a in AXES}, {a: 370.0 for a in AXES}))
            self._targets = {a: self.stage.desired_position(a) for a in AXES}
        except DriverError as error:
            _log.warning("stage: could not re-read its state: %s", error)
            self._targets = None
        return True

    def position(self) -> dict[int, float]:
        """Encoder readback ``{1: view, 2: theta_i, 3: phi_i}`` [deg]."""
        self._position = self.stage.positions(AXES)
        return dict(self._position)

    def home(self) -> dict[int, float]:
        """Home the three axes (``OR``), in an order that respects the separation."""
        self._require_initialized()
        start = dict(self._targets) if self._targets else {a: self.stage.desired_position(a) for a in AXES}
        plan = plan_moves(start, self.home_position, self.min_separation, self.limits)
        if plan is None:
            raise GeometryError("no collision-free order of homing moves exists from here")
        current = dict(start)
        for stage in plan.stages:
            goal = dict(current)
            goal.update(dict(stage))
            is_home = all(self.home_position[a] == t for a, t in stage)
            line = ";".join((f"{a}OR" if is_home else f"{a}PA{t:.5f}") for a, t in stage)
            self.stage.send(line)
            self.stage.wait(0.0, timeout=self._move_timeout(current, goal))
            current = goal
        self._targets = dict(self.home_position)
        self._position = self.stage.positions(AXES)
        self._set_view(self._position[AXIS_VIEW])
        return dict(self._position)

    # -- camera ---------------------------------------------------------------------------
    def roi_for_view(self, view: float) -> Roi:
        """The radiance window at camera angle ``view`` (see :func:`roi_for_view`)."""
        self._require_initialized()
        return roi_for_view(self.info, view, fraction=self.roi_fraction,
                            sample_size_mm=self.sample_size_mm, margin_px=self.roi_margin_px)

    def _set_view(self, view: float) -> None:
        roi = self.roi_for_view(view)
        if roi != self._roi:
            self.camera.set_roi(roi)
            self._roi = roi
        self._view = float(view)

    def _set_exposure(self, seconds: float) -> None:
        if seconds != self._exposure:
            self.camera.set_exposure(seconds)
            self._exposure = seconds

    def _expose(self, seconds: float) -> RoiStats:
        """One exposure: ROI statistics, and the lamp monitor's reading kept for it."""
        self._set_exposure(seconds)
        self.camera.acquire()
        self._last_monitor = self.camera.monitor() if self.has_monitor else math.nan
        return self.camera.roi_stats()

    def frame(self, exposure: float | None = None) -> np.ndarray:
        """Take one exposure (current or given exposure [s]) and return the full frame [DN]."""
        if exposure is not None:
            self._set_exposure(float(exposure))
        self.camera.acquire()
        return self.camera.frame()

    def roi_frame(self, exposure: float | None = None) -> np.ndarray:
        """Take one exposure (current or given exposure [s]) and return the ROI's pixels [DN]."""
        if exposure is not None:
            self._set_exposure(float(exposure))
        self.camera.acquire()
        return self.camera.roi_frame(self._roi)

    def dark_frame(self, exposure: float | None = None, *, full: bool = False, roi_pixels: bool = False) -> DarkLevel:
        """Take a dark exposure (shutter closed) at the current gain.

        Parameters
        ----------
        exposure : float, optional
            Exposure time [s] (default: the current one).
        full : bool
            Also transfer the full frame (``FRAME?``) into ``DarkLevel.frame``.
        roi_pixels : bool
            Also transfer the ROI's pixels (``ROI:DATA?``) into ``DarkLevel.frame``.
        """
        if exposure is not None:
            self._set_exposure(float(exposure))
        self.camera.close_shutter()
        try:
            self.camera.acquire()
            monitor = self.camera.monitor() if self.has_monitor else math.nan
            stats = self.camera.roi_stats()
            frame = self.camera.frame() if full else (self.camera.roi_frame(self._roi) if roi_pixels else None)
        finally:
            self.camera.open_shutter()
        dark = DarkLevel(self._exposure, self.gain, stats, "measured", frame, monitor)
        self._darks[(self._exposure, self.gain, self._roi)] = dark
        return dark

    def calibrate_dark(self, exposures=(0.001, 0.01, 0.1, 1.0)) -> tuple[float, float]:
        """Fit the dark ROI level as ``offset + rate * t`` over ``exposures`` [s].

        Afterwards :meth:`measure` with ``dark="auto"`` uses the model instead of taking a
        dark frame per exposure (valid for the current gain; the fit is forgotten when the
        gain changes). The DSNU averaged over different ROIs differs by far less than the
        temporal noise of one ROI mean, so one fit serves every ROI.

        Returns
        -------
        (offset, rate) : (float, float)
            Dark offset [DN] and dark-signal rate [DN/s].
        """
        t = np.asarray(exposures, dtype=float)
        levels = np.array([self.dark_frame(float(e)).level for e in t])
        rate, offset = np.polyfit(t, levels, 1)
        self._dark_model = (self.gain, float(offset), float(rate))
        return float(offset), float(rate)

    def _dark(self, exposure: float, mode: str) -> DarkLevel:
        key = (exposure, self.gain, self._roi)
        if mode == "none":
            return DarkLevel(exposure, self.gain, RoiStats(0.0, 0.0, 1, 0), "none")
        if mode in ("auto", "model") and self._dark_model and self._dark_model[0] == self.gain:
            _, offset, rate = self._dark_model
            return DarkLevel(exposure, self.gain, RoiStats(offset + rate * exposure, 0.0, 1, 0), "model")
        if mode == "model":
            raise DriverError("dark='model' needs calibrate_dark() at the current gain first")
        if mode == "auto" and key in self._darks:
            return dataclasses.replace(self._darks[key], source="cached")
        if mode in ("auto", "measure"):
            return self.dark_frame(exposure)
        raise ValueError(f"dark={mode!r} is not one of 'auto', 'measure', 'model', 'none'")

    def _auto_exposure(self, target_fraction: float | None = None, max_exposure: float | None = None,
                       start: float | None = None, max_attempts: int = 8) -> tuple[float, RoiStats, int]:
        """Find a ladder exposure with the ROI mean in the window and nothing saturated.

        ``target_fraction`` (default :attr:`target_fraction`, window :attr:`exposure_window`;
        another aim gets the window of :func:`~drivers.rig_checks.exposure_window`),
        ``max_exposure`` [s] (default the upper exposure limit; never above it) and the
        first exposure tried ``start`` [s] (default the current exposure) override the
        rig's settings for this call.
        """
        max_dn = self.info.max_dn
        if target_fraction is None or target_fraction == self.target_fraction:
            fraction, window = self.target_fraction, self.exposure_window
        else:
            fraction, window = float(target_fraction), exposure_window(float(target_fraction))
        low, high = (f * max_dn for f in window)
        target = fraction * max_dn
        t_min, t_max = self.exposure_limits
        if max_exposure is not None:
            if not max_exposure >= t_min:
                raise ValueError(f"max_exposure={max_exposure!r} s is below the shortest exposure {t_min:g} s")
            t_max = min(t_max, float(max_exposure))
        offset = self._dark_model[1] if self._dark_model else None
        first = start if start is not None else (self._exposure or 0.01)
        t = exposure_ladder_floor(min(max(first, t_min), t_max))
        tried: dict[float, RoiStats] = {}
        for attempt in range(1, max_attempts + 1):
            stats = self._expose(t)
            tried[t] = stats
            if offset is None:
                # Offset for the exposure search only (the dark-signal part is small):
                # any dark level already known, else a dark frame at this exposure.
                known = [d.level for (_, g, _), d in self._darks.items() if g == self.gain]
                offset = min(known) if known else self._dark(t, "auto").level
            if stats.saturated == 0 and low <= stats.mean <= high:
                return t, stats, attempt
            signal = stats.mean - offset
            if stats.saturated > 0 or stats.mean > high:
                scale = min(0.5, (target - offset) / max(signal, 1e-9))
            else:
                scale = (target - offset) / max(signal, 1e-3 * (target - offset))
            new_t = exposure_ladder_floor(min(max(t * scale, t_min), t_max))
            if new_t == t or new_t in tried:
                break
            t = new_t
        good = [(tt, s) for tt, s in tried.items() if s.saturated == 0]
        if good:  # the brightest unsaturated frame: a weak signal is still data (flagged later)
            tt, s = max(good, key=lambda item: item[1].mean)
            if s.mean - offset < 0.02 * max_dn:
                _log.info("automatic exposure: weak signal %.1f DN at %g s (limit %g s)", s.mean - offset, tt, t_max)
            if tt != self._exposure:
                s = self._expose(tt)
            return tt, s, attempt
        raise ExposureError(
            f"automatic exposure failed within {t_min:g}..{t_max:g} s: every frame saturated: "
            + ", ".join(f"{tt:g} s -> mean {s.mean:.1f} DN, {s.saturated} saturated" for tt, s in tried.items())
        )

    def measure(
        self,
        theta_i: float | None = None,
        phi_i: float | None = None,
        view: float | None = None,
        *,
        exposure: float | str = "auto",
        dark: str = "auto",
        target_fraction: float | None = None,
        max_exposure: float | None = None,
        start_exposure: float | None = None,
        settle_time: float = 0.0,
    ) -> Measurement:
        """Measure the sample radiance at a geometry (moving there first if given).

        Parameters
        ----------
        theta_i, phi_i, view : float, optional
            Geometry [deg]; all three or none (measure where the rig is).
        exposure : float or "auto"
            Exposure time [s], or automatic exposure (no saturation, enough signal).
        dark : {"auto", "measure", "model", "none"}
            Dark level: ``"auto"`` uses the dark model of :meth:`calibrate_dark` if there
            is one, else a dark frame at the same exposure, gain and ROI (cached);
            ``"measure"`` always takes a dark frame.
        target_fraction, max_exposure, start_exposure : float, optional
            Automatic exposure only: aim of the raw ROI mean as a fraction of full scale
            [-], longest exposure [s] and first exposure tried [s] (defaults: the rig's
            ``target_fraction``, its upper exposure limit and the current exposure).
        settle_time : float
            Wait after the move before exposing [s] (in the instruments' time).

        Returns
        -------
        Measurement
        """
        given = [v is not None for v in (theta_i, phi_i, view)]
        if any(given) and not all(given):
            raise ValueError("give theta_i, phi_i and view together, or none of them")
        time_start = time.time()
        if all(given):
            self.move_to(theta_i, phi_i, view)
            if settle_time > 0:
                self.wait(settle_time)
        elif self._targets is None or self._view is None:
            raise DriverError("the rig has no known geometry; call move_to() or measure(theta_i, phi_i, view)")
        else:
            theta_i, phi_i, view = (self._targets[a] for a in (AXIS_THETA_I, AXIS_PHI_I, AXIS_VIEW))
        # Lamp readings first: a dead lamp fails fast instead of driving the automatic
        # exposure to its limit.
        voltage = self.lamp.measured_voltage()
        current = self.lamp.measured_current()
        if current <= 0.0:
            self.lamp.check_lamp()  # raises LampError on a burnt-out lamp
            raise LampError(0, "lamp current is 0 A: the output is off or the lamp is open", "MEAS:CURR?")
        if exposure == "auto":
            t, stats, attempts = self._auto_exposure(target_fraction, max_exposure, start_exposure)
        else:
            t = float(exposure)
            stats, attempts = self._expose(t), 1
        dark_level = self._dark(t, dark)
        signal = stats.mean - dark_level.level
        per_second = self.radiance_scale / (t * self.gain)
        error = math.sqrt(stats.std**2 / max(stats.pixels, 1) + dark_level.stats.std**2 / max(dark_level.stats.pixels, 1))
        theta_r, phi_r = camera_direction(view)
        return Measurement(
            theta_i=float(theta_i), phi_i=float(phi_i), view=float(view),
            theta_r=theta_r, phi_r=phi_r,
            stage_position=dict(self._position),
            roi=self._roi,
            roi_mean=stats.mean, roi_std=stats.std, roi_pixels=stats.pixels, roi_saturated=stats.saturated,
            exposure=t, gain=self.gain,
            dark_level=dark_level.level, dark_std=dark_level.stats.std, dark_source=dark_level.source,
            signal=signal, radiance=signal * per_second, radiance_error=error * per_second,
            lamp_voltage=voltage, lamp_current=current,
            time_start=time_start, time_end=time.time(), attempts=attempts, monitor=self._last_monitor,
            dark_monitor=dark_level.monitor if dark_level.source == "measured" else math.nan,
        )

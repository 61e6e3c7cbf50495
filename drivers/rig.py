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
the ADC maximum, aiming at ``target_fraction``, with no saturated pixel in the ROI.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .camera import Camera, Roi, RoiStats, SensorInfo
from .errors import DriverError, ExposureError, GeometryError, LampError, StageError
from .esp300 import ESP300
from .lamp import Lamp
from .rig_geometry import (
    AXES,
    AXIS_PHI_I,
    AXIS_THETA_I,
    AXIS_VIEW,
    axis_targets,
    camera_direction,
    check_targets,
    plan_moves,
)

__all__ = ["Rig", "Measurement", "DarkLevel", "roi_for_view", "sample_image_size"]

_log = logging.getLogger(__name__)

#: Side of the square sample (2 inch) [mm].
SAMPLE_SIZE_MM = 50.8
#: Home positions of the axes (docs/protocol.md) [deg].
HOME = {AXIS_VIEW: 0.0, AXIS_THETA_I: 45.0, AXIS_PHI_I: 0.0}


def sample_image_size(info: SensorInfo, view: float, sample_size_mm: float = SAMPLE_SIZE_MM) -> tuple[float, float]:
    """Width (along the swing plane, image x) and height of the sample's image [pixel].

    ``s cos(theta_r) m / p`` by ``s m / p`` with the far-field magnification ``m = f / D``
    and pixel pitch ``p`` (docs/protocol.md, "Image geometry").

    Examples
    --------
    >>> info = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)
    >>> [round(v, 1) for v in sample_image_size(info, 60.0)]
    [138.9, 277.8]
    """
    scale = info.focal_length_mm / info.distance_mm / (info.pixel_pitch_um * 1e-3)
    theta_r = abs(float(view))
    return sample_size_mm * math.cos(math.radians(theta_r)) * scale, sample_size_mm * scale


def roi_for_view(
    info: SensorInfo,
    view: float,
    *,
    fraction: float = 0.5,
    sample_size_mm: float = SAMPLE_SIZE_MM,
    margin_px: float = 2.0,
) -> Roi:
    """ROI covering the central ``fraction`` x ``fraction`` of the sample at camera angle ``view``.

    The window is ``fraction * s`` on the sample in both directions; in the image it is
    foreshortened by ``cos(theta_r)`` along x. It is centred on the image centre (where
    the sample centre is imaged), with even pixel sizes.

    Raises
    ------
    GeometryError
        If the ROI would not lie inside the sample's image with ``margin_px`` pixels to
        spare on each side, or would be narrower than 2 pixels (grazing view).
    ValueError
        If ``fraction`` is not in (0, 1].

    Examples
    --------
    >>> info = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)
    >>> roi_for_view(info, 0.0)
    Roi(x0=187, y0=171, width=138, height=138)
    """
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction={fraction!r} is invalid; it must be in (0, 1]")
    sample_w, sample_h = sample_image_size(info, view, sample_size_mm)
    # Even sizes keep the ROI symmetric about the image centre, which lies on a pixel
    # edge for the even sensor dimensions (docs/protocol.md); pixel quantisation changes
    # the covered sample area by at most one pixel column/row.
    width = max(2, 2 * int(round(fraction * sample_w / 2.0)))
    height = max(2, 2 * int(round(fraction * sample_h / 2.0)))
    x0 = int(round(info.width / 2.0 - width / 2.0))
    y0 = int(round(info.height / 2.0 - height / 2.0))
    roi = Roi(x0, y0, width, height)
    reason = roi_problem(info, view, roi, sample_size_mm=sample_size_mm, margin_px=margin_px)
    if reason:
        raise GeometryError(reason)
    return roi


def roi_problem(
    info: SensorInfo, view: float, roi: Roi, *, sample_size_mm: float = SAMPLE_SIZE_MM, margin_px: float = 2.0
) -> str | None:
    """Why ``roi`` is not a valid radiance window on the sample's image at ``view``, or None."""
    sample_w, sample_h = sample_image_size(info, view, sample_size_mm)
    cx, cy = info.width / 2.0, info.height / 2.0
    left, right = cx - sample_w / 2 + margin_px, cx + sample_w / 2 - margin_px
    top, bottom = cy - sample_h / 2 + margin_px, cy + sample_h / 2 - margin_px
    if roi.width < 2 or roi.height < 2:
        return (
            f"the ROI at view={view:g} deg would be {roi.width} x {roi.height} pixels; the "
            "sample's image is too narrow at this grazing angle (at least 2 x 2 needed)"
        )
    if roi.x0 < left or roi.x0 + roi.width > right or roi.y0 < top or roi.y0 + roi.height > bottom:
        return (
            f"ROI {roi} is not inside the sample's image at view={view:g} deg "
            f"(x {left:.1f}..{right:.1f}, y {top:.1f}..{bottom:.1f} with a {margin_px:g}-pixel margin)"
        )
    if roi.x0 < 0 or roi.y0 < 0 or roi.x0 + roi.width > info.width or roi.y0 + roi.height > info.height:
        return f"ROI {roi} extends beyond the {info.width} x {info.height} sensor"
    return None


def exposure_ladder_floor(seconds: float, steps_per_decade: int = 12) -> float:
    """Largest exposure of the ladder ``10**(k / steps_per_decade)`` not above ``seconds`` [s]."""
    k = math.floor(math.log10(seconds) * steps_per_decade + 1e-9)
    return float(f"{10 ** (k / steps_per_decade):.4g}")


@dataclass(frozen=True)
class DarkLevel:
    """Dark (shutter closed) ROI statistics at one exposure and gain.

    Attributes
    ----------
    exposure : float
        Exposure time [s].
    gain : float
        Analog gain factor [-].
    stats : RoiStats
        ROI statistics of the dark frame [DN].
    source : str
        ``"measured"``, ``"cached"`` or ``"model"`` (from :meth:`Rig.calibrate_dark`).
    frame : numpy.ndarray or None
        The full dark frame when requested [DN].
    """

    exposure: float
    gain: float
    stats: RoiStats
    source: str = "measured"
    frame: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def level(self) -> float:
        """Mean dark level in the ROI [DN]."""
        return self.stats.mean


@dataclass(frozen=True)
class Measurement:
    """One radiance measurement at one geometry (all angles in degrees).

    Attributes
    ----------
    theta_i, phi_i, view : float
        Requested geometry: lamp polar angle, lamp azimuth, signed camera angle [deg].
    theta_r, phi_r : float
        Camera direction implied by ``view`` [deg].
    stage_position : dict
        Encoder readback ``{1: view, 2: theta_i, 3: phi_i}`` after the move [deg].
    roi : Roi
        Region of interest [pixel].
    roi_mean, roi_std : float
        Raw ROI mean and standard deviation of the light frame [DN].
    roi_pixels, roi_saturated : int
        Pixel count and saturated pixel count of the ROI [-].
    exposure : float
        Exposure time [s].
    gain : float
        Analog gain factor [-].
    dark_level, dark_std : float
        Dark ROI mean and standard deviation at the same exposure and gain [DN].
    dark_source : str
        How the dark level was obtained (see :class:`DarkLevel`).
    signal : float
        ``roi_mean - dark_level`` [DN].
    radiance : float
        Relative radiance: ``signal / (exposure * gain) * radiance_scale`` [DN/s per
        ROI pixel at unit gain, times the scale].
    radiance_error : float
        One-sigma uncertainty of ``radiance`` from the ROI statistics (spatial standard
        deviation over the square root of the pixel count, light and dark) [same unit].
    lamp_voltage, lamp_current : float
        Lamp supply readings taken just before the exposure [V], [A].
    time_start, time_end : float
        Wall-clock times (``time.time()``) around the measurement [s].
    attempts : int
        Exposures taken to settle the automatic exposure [-].
    """

    theta_i: float
    phi_i: float
    view: float
    theta_r: float
    phi_r: float
    stage_position: dict
    roi: Roi
    roi_mean: float
    roi_std: float
    roi_pixels: int
    roi_saturated: int
    exposure: float
    gain: float
    dark_level: float
    dark_std: float
    dark_source: str
    signal: float
    radiance: float
    radiance_error: float
    lamp_voltage: float
    lamp_current: float
    time_start: float
    time_end: float
    attempts: int = 1

    def to_dict(self) -> dict[str, Any]:
        """Flat dictionary of plain numbers and strings (for CSV/JSON records)."""
        out = dataclasses.asdict(self)
        roi = out.pop("roi")
        out.update({f"roi_{k}": v for k, v in roi.items()})
        position = out.pop("stage_position")
        out.update({
            "stage_view": position.get(AXIS_VIEW, math.nan),
            "stage_theta_i": position.get(AXIS_THETA_I, math.nan),
            "stage_phi_i": position.get(AXIS_PHI_I, math.nan),
        })
        return out


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
            self._acceleration[axis] = self.stage.acceleration(axis)
        self._targets = {a: self.stage.desired_position(a) for a in AXES}
        self.info = self.camera.sensor_info()
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

    def wait_lamp_stable(self, settle_time: float = 600.0, tolerance: float = 2e-3) -> dict[str, float]:
        """Wait for the lamp to warm up, then check that its supply readings are steady.

        The lamp output settles with the filament's thermal time constant (120 s for the
        rig's lamp, docs/protocol.md); the default wait of 600 s leaves less than 0.02 %
        of a 2 % warm-up deficit. Afterwards the current is read twice, 1 s apart, and
        must agree within ``tolerance`` (relative).

        Returns
        -------
        dict
            ``voltage`` [V] and ``current`` [A] after the wait.

        Raises
        ------
        LampError
            If the output is off, the lamp reports a fault, or the current is unsteady.
        """
        if not self.lamp.output_is_on():
            raise LampError(0, "lamp output is off; call lamp_on() first", "OUTP?")
        self.wait(settle_time)
        first = self.lamp.measured_current()
        self.wait(1.0)
        second = self.lamp.measured_current()
        self.lamp.check_lamp()
        if first <= 0 or abs(second - first) > tolerance * first:
            raise LampError(
                0, f"lamp current not steady after {settle_time:g} s: {first:.5g} A then {second:.5g} A",
                "MEAS:CURR?",
            )
        return {"voltage": self.lamp.measured_voltage(), "current": second}

    # -- geometry -------------------------------------------------------------------------
    def _require_initialized(self) -> None:
        if not self.limits or self.info is None:
            raise DriverError("the rig is not initialized; call initialize() (Rig.open does)")

    def check_geometry(self, theta_i: float, phi_i: float, view: float) -> str | None:
        """Why the geometry cannot be measured (travel limits, separation), or ``None``.

        Nothing is sent to the instruments.
        """
        self._require_initialized()
        targets = axis_targets(theta_i, phi_i, view)
        reason = check_targets(targets, self.limits, self.min_separation)
        if reason:
            return reason
        if not math.isfinite(view):
            return f"view={view!r} is not finite"
        try:
            roi_for_view(self.info, view, fraction=self.roi_fraction,
                         sample_size_mm=self.sample_size_mm, margin_px=self.roi_margin_px)
        except GeometryError as exc:
            return str(exc)
        return None

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
        """Move lamp and camera to a measurement geometry and wait until stopped.

        The geometry is checked first (:meth:`check_geometry`); a refused geometry raises
        :class:`GeometryError` and nothing is sent.

        Returns
        -------
        dict
            Encoder readback ``{1: view, 2: theta_i, 3: phi_i}`` [deg].

        Raises
        ------
        GeometryError
            Outside the travel limits, too close to the lamp, or no ROI on the sample.
        StageError
            If the controller refuses a command or reports an error during the move.
        """
        reason = self.check_geometry(theta_i, phi_i, view)
        if reason:
            raise GeometryError(reason)
        end = axis_targets(theta_i, phi_i, view)
        start = dict(self._targets) if self._targets else {a: self.stage.desired_position(a) for a in AXES}
        plan = plan_moves(start, end, self.min_separation, self.limits)
        if plan is None:
            raise GeometryError(
                f"no sequence of axis moves reaches theta_i={theta_i:g}, phi_i={phi_i:g}, "
                f"view={view:g} from {start} without violating the {self.min_separation:g}-deg separation"
            )
        current = dict(start)
        try:
            for stage in plan.stages:
                line = ";".join(f"{axis}PA{target:.5f}" for axis, target in stage)
                self.stage.send(line)
                goal = dict(current)
                goal.update(dict(stage))
                self.stage.wait(0.0, timeout=self._move_timeout(current, goal))
                current = goal
        except StageError:
            self._targets = None  # re-read the targets before the next move
            raise
        self._targets = dict(end)
        self._position = self.stage.positions(AXES)
        self._set_view(view)
        return dict(self._position)

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
        self._set_exposure(seconds)
        self.camera.acquire()
        return self.camera.roi_stats()

    def frame(self, exposure: float | None = None) -> np.ndarray:
        """Take one exposure (current or given exposure [s]) and return the full frame [DN]."""
        if exposure is not None:
            self._set_exposure(float(exposure))
        self.camera.acquire()
        return self.camera.frame()

    def dark_frame(self, exposure: float | None = None, *, full: bool = False) -> DarkLevel:
        """Take a dark exposure (shutter closed) at the current gain.

        Parameters
        ----------
        exposure : float, optional
            Exposure time [s] (default: the current one).
        full : bool
            Also transfer the full frame (``FRAME?``) into ``DarkLevel.frame``.
        """
        if exposure is not None:
            self._set_exposure(float(exposure))
        self.camera.close_shutter()
        try:
            self.camera.acquire()
            stats = self.camera.roi_stats()
            frame = self.camera.frame() if full else None
        finally:
            self.camera.open_shutter()
        dark = DarkLevel(self._exposure, self.gain, stats, "measured", frame)
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

    def _auto_exposure(self, max_attempts: int = 8) -> tuple[float, RoiStats, int]:
        """Find a ladder exposure with the ROI mean in the window and nothing saturated."""
        max_dn = self.info.max_dn
        low, high = (f * max_dn for f in self.exposure_window)
        target = self.target_fraction * max_dn
        t_min, t_max = self.exposure_limits
        offset = self._dark_model[1] if self._dark_model else None
        t = exposure_ladder_floor(min(max(self._exposure or 0.01, t_min), t_max))
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
        if good:
            tt, s = max(good, key=lambda item: item[1].mean)
            if s.mean - offset >= 0.02 * max_dn:
                if tt != self._exposure:
                    s = self._expose(tt)
                return tt, s, attempt
        raise ExposureError(
            f"automatic exposure failed within {t_min:g}..{t_max:g} s: tried "
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
            t, stats, attempts = self._auto_exposure()
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
            time_start=time_start, time_end=time.time(), attempts=attempts,
        )

"""Firmware of the emulated CCD camera (SCPI dialect of docs/protocol.md, section 2)."""
from __future__ import annotations

from typing import Protocol

import numpy as np

from .ccd import CCDSensor, Exposure
from .clock import SimClock
from .monitor import LampMonitor
from .scpi import ScpiError, ScpiInstrument, definite_length_block, expect_args, format_number
from .status import OPERATION_BITS, QUESTIONABLE_BITS
from .world import Optics

__all__ = ["CameraFirmware", "roi_statistics"]

EXPOSURE_RANGE_S = (1e-5, 60.0)
GAIN_RANGE = (1.0, 16.0)
DEFAULT_EXPOSURE_S = 0.01


class Scene(Protocol):
    """What the camera looks at (:class:`drivers.emulator.rig.Scene`)."""

    def lamp_exposure(self, t_start: float, exposure_s: float) -> float:
        """Lamp output of one exposure, flicker included [-]."""

    def photons(self, t_start: float, exposure_s: float, lamp: float) -> "np.ndarray | float":
        """Mean photons per pixel of an exposure lit with lamp output ``lamp``."""


def roi_statistics(frame: np.ndarray, saturated: np.ndarray, roi: tuple[int, int, int, int]) -> tuple[float, float, int, int]:
    """Mean [DN], sample standard deviation (ddof=1, 0 for one pixel) [DN], pixel count and
    saturated-pixel count of ``frame`` inside ``roi = (x0, y0, width, height)``.

    Examples
    --------
    >>> f = np.arange(12, dtype=np.uint16).reshape(3, 4)
    >>> roi_statistics(f, np.zeros((3, 4), bool), (1, 1, 2, 2))
    (7.5, 2.3804761428476167, 4, 0)
    """
    x0, y0, w, h = roi
    window = frame[y0:y0 + h, x0:x0 + w].astype(np.float64)
    n = window.size
    std = float(window.std(ddof=1)) if n > 1 else 0.0
    return float(window.mean()), std, n, int(saturated[y0:y0 + h, x0:x0 + w].sum())


class CameraFirmware(ScpiInstrument):
    """SCPI command set of the CCD camera.

    ``ACQuire`` is an overlapped command (IEEE 488.2 12): it starts the exposure and
    returns; the exposure and its readout complete ``EXP + 50 ms`` of simulated time later.
    Every device command sent meanwhile (a setting, ``ROI:STAT?``, ``FRAMe?``, another
    ``ACQ``) and ``*WAI``, ``*OPC?``, ``*TST?`` wait for that moment; the status commands
    do not, so ``STAT:OPER:COND?`` reports bit 4 (MEASuring) while the exposure runs and
    ``*OPC`` sets the OPC event bit when it has completed.  STATus:QUEStionable bit 9 is set
    while the ROI of the last frame holds saturated pixels; ``*TST?`` replies 1 while the
    camera has an internal fault.

    Parameters
    ----------
    clock : SimClock
        Shared simulated clock.
    sensor : CCDSensor
        The EMVA 1288 sensor model.
    optics : Optics
        Rig layout (``SENS:INFO?``).
    scene : callable
        ``scene(t_start, exposure_s)``: mean photons per pixel of an exposure starting at
        ``t_start`` with the shutter open.
    rng : numpy.random.Generator
        Temporal noise source.
    serial : str
        Serial number in ``*IDN?``.
    monitor : LampMonitor, optional
        The lamp monitor triggered with every exposure (``MONitor?``); None: no monitor
        fitted (``MONitor?`` is then an undefined header, ``*OPT?`` replies ``0``).
    """

    def __init__(self, clock: SimClock, sensor: CCDSensor, optics: Optics, scene: Scene,
                 rng: np.random.Generator, serial: str = "SN0001", monitor: LampMonitor | None = None) -> None:
        super().__init__()
        self.monitor = monitor
        self.last_monitor_v: float | None = None
        self.clock = clock
        self.sensor = sensor
        self.optics = optics
        self.scene = scene
        self.rng = rng
        self.serial = serial
        self.fault = False  # side channel: an internal camera fault (ACQ fails with -200)
        self.last: Exposure | None = None
        self.busy_until: float | None = None
        self._saturation_cache: tuple[int, tuple[int, int, int, int], bool] | None = None
        self.reset()
        self.add_setting("EXPosure", lambda: self.exposure_s, self._put_exposure, *EXPOSURE_RANGE_S,
                         DEFAULT_EXPOSURE_S, unit="S")
        self.add_setting("GAIN", lambda: self.gain, self._put_gain, *GAIN_RANGE, 1.0)
        self.add("SHUTter", False, self._set_shutter)
        self.add("SHUTter", True, lambda a: self._no_args(a) or ("OPEN" if self.shutter_open else "CLOSE"))
        self.add("ROI", False, self._set_roi)
        self.add("ROI", True, lambda a: self._no_args(a) or ",".join(str(v) for v in self.roi))
        self.add("ACQuire", False, self._acquire)
        self.add("ROI:STATistics", True, self._roi_stat)
        self.add("FRAMe", True, self._frame)
        self.add("ROI:DATA", True, self._roi_data)
        self.add("SENSe:INFO", True, self._info)
        self.add("TEMPerature", True, lambda a: self._no_args(a) or format_number(self.sensor.params.temperature_c))
        self.add("*OPT", True, lambda a: self._no_args(a) or ("MON" if self.monitor is not None else "0"), waits=False)
        if self.monitor is not None:
            self.add("MONitor", True, self._monitor)

    def identity(self) -> str:
        return f"GONIO,CCD-512,{self.serial},1.0"

    def reset(self) -> None:
        self.exposure_s = DEFAULT_EXPOSURE_S
        self.gain = 1.0
        self.shutter_open = True
        self.roi = (0, 0, self.optics.width, self.optics.height)
        self.last = None
        self.busy_until = None  # *RST abandons an exposure in progress

    # -- status (drivers.emulator.status) -------------------------------------------------
    def pending_until(self) -> float | None:
        """End of the exposure in progress (exposure + readout) [s], None when idle."""
        return self.busy_until

    def operation_condition(self) -> int:
        """Bit 4 (MEASuring) while an exposure or its readout is in progress."""
        exposing = self.busy_until is not None and self.clock.now() < self.busy_until
        return (1 << OPERATION_BITS["MEASURING"]) if exposing else 0

    def questionable_condition(self) -> int:
        """Bit 9 while the ROI of the last frame holds saturated pixels."""
        return (1 << QUESTIONABLE_BITS["DEVICE"]) if self._roi_saturated() else 0

    def _roi_saturated(self) -> bool:
        """Whether the last frame has a saturated pixel inside the ROI (cached per frame and ROI)."""
        if self.last is None:
            return False
        key = (id(self.last), self.roi)
        cache = self._saturation_cache
        if cache is None or cache[:2] != key:
            x0, y0, w, h = self.roi
            cache = (*key, bool(self.last.region(x0, y0, w, h)[1].any()))
            self._saturation_cache = cache
        return cache[2]

    def self_test(self) -> int:
        """1 while the camera has an internal fault, else 0."""
        return 1 if self.fault else 0

    @staticmethod
    def _no_args(args: list[str]) -> None:
        expect_args(args, 0)

    def _put_exposure(self, seconds: float) -> None:
        self.exposure_s = seconds

    def _put_gain(self, gain: float) -> None:
        self.gain = gain

    def _set_shutter(self, args: list[str]) -> None:
        expect_args(args, 1)
        word = args[0].upper()
        if word in ("OPEN", "1", "ON"):
            self.shutter_open = True
        elif word in ("CLOS", "CLOSE", "CLOSED", "0", "OFF"):
            self.shutter_open = False
        else:
            raise ScpiError(-104, f"SHUT expects OPEN or CLOSE, got {args[0]!r}")

    def _set_roi(self, args: list[str]) -> None:
        """``ROI <x0>,<y0>,<width>,<height>`` [pixels]: four strict integers inside the sensor.

        A parameter that is not an integer (``++1``, ``1.5``, ``1e2``) is -104; a rectangle
        that is not inside the sensor (``x0`` or ``y0`` negative, ``width`` or ``height``
        below 1, right or bottom edge beyond the sensor) is -222.
        """
        expect_args(args, 4)
        names = ("x0", "y0", "width", "height")
        x0, y0, w, h = (self.parse_integer(text, f"ROI {name}") for name, text in zip(names, args))
        width, height = self.optics.width, self.optics.height
        if x0 < 0 or y0 < 0 or w < 1 or h < 1 or x0 + w > width or y0 + h > height:
            raise ScpiError(-222, f"ROI {x0},{y0},{w},{h} outside the {width}x{height} sensor")
        self.roi = (x0, y0, w, h)

    def _acquire(self, args: list[str]) -> None:
        expect_args(args, 0)
        if self.fault:
            raise ScpiError(-200, "camera fault")
        t0 = self.clock.now()
        lamp = self.scene.lamp_exposure(t0, self.exposure_s)
        photons = self.scene.photons(t0, self.exposure_s, lamp) if self.shutter_open else 0.0
        self.last = self.sensor.expose(photons, self.exposure_s, self.gain, self.rng)
        if self.monitor is not None:  # the monitor sees the lamp whatever the shutter does
            self.last_monitor_v = self.monitor.read(lamp, self.exposure_s)
        self.busy_until = t0 + self.exposure_s + self.sensor.params.readout_s  # overlapped: see the class doc

    def _monitor(self, args: list[str]) -> str:
        expect_args(args, 0)
        self._need_frame()
        return f"{self.last_monitor_v:.7f}"

    def _need_frame(self) -> Exposure:
        if self.last is None:
            raise ScpiError(-221, "no frame acquired")
        return self.last

    def _roi_stat(self, args: list[str]) -> str:
        expect_args(args, 0)
        shot = self._need_frame()
        x0, y0, w, h = self.roi
        frame, saturated = shot.region(x0, y0, w, h)
        mean, std, n, sat = roi_statistics(frame, saturated, (0, 0, w, h))
        return f"{mean:.4f},{std:.4f},{n},{sat}"

    def _frame(self, args: list[str]) -> bytes:
        expect_args(args, 0)
        shot = self._need_frame()
        return definite_length_block(shot.frame.astype("<u2").tobytes())

    def _roi_data(self, args: list[str]) -> bytes:
        expect_args(args, 0)
        shot = self._need_frame()
        x0, y0, w, h = self.roi
        return definite_length_block(shot.region(x0, y0, w, h)[0].astype("<u2").tobytes())

    def _info(self, args: list[str]) -> str:
        expect_args(args, 0)
        o = self.optics
        fields = (o.width, o.height, self.sensor.params.bits, o.pixel_pitch_um, o.focal_length_mm, o.distance_mm)
        return ",".join(format_number(v) for v in fields)

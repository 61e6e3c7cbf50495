"""Firmware of the emulated CCD camera (SCPI dialect of docs/protocol.md, section 2)."""
from __future__ import annotations

from typing import Callable

import numpy as np

from .ccd import CCDSensor, Exposure
from .clock import SimClock
from .scpi import ScpiError, ScpiInstrument, definite_length_block, expect_args, format_number, parse_number
from .world import Optics

__all__ = ["CameraFirmware", "roi_statistics"]

EXPOSURE_RANGE_S = (1e-5, 60.0)
GAIN_RANGE = (1.0, 16.0)
DEFAULT_EXPOSURE_S = 0.01

#: ``scene(t_start, exposure_s) -> mean photons per pixel`` (array (height, width) or scalar).
Scene = Callable[[float, float], "np.ndarray | float"]


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
    """

    def __init__(self, clock: SimClock, sensor: CCDSensor, optics: Optics, scene: Scene,
                 rng: np.random.Generator, serial: str = "SN0001") -> None:
        super().__init__()
        self.clock = clock
        self.sensor = sensor
        self.optics = optics
        self.scene = scene
        self.rng = rng
        self.serial = serial
        self.fault = False  # side channel: an internal camera fault (ACQ fails with -200)
        self.last: Exposure | None = None
        self.reset()
        self.add("EXPosure", False, self._set_exposure)
        self.add("EXPosure", True, lambda a: self._no_args(a) or format_number(self.exposure_s))
        self.add("GAIN", False, self._set_gain)
        self.add("GAIN", True, lambda a: self._no_args(a) or format_number(self.gain))
        self.add("SHUTter", False, self._set_shutter)
        self.add("SHUTter", True, lambda a: self._no_args(a) or ("OPEN" if self.shutter_open else "CLOSE"))
        self.add("ROI", False, self._set_roi)
        self.add("ROI", True, lambda a: self._no_args(a) or ",".join(str(v) for v in self.roi))
        self.add("ACQuire", False, self._acquire)
        self.add("ROI:STATistics", True, self._roi_stat)
        self.add("FRAMe", True, self._frame)
        self.add("SENSe:INFO", True, self._info)
        self.add("TEMPerature", True, lambda a: self._no_args(a) or format_number(self.sensor.params.temperature_c))

    def identity(self) -> str:
        return f"GONIO,CCD-512,{self.serial},1.0"

    def reset(self) -> None:
        self.exposure_s = DEFAULT_EXPOSURE_S
        self.gain = 1.0
        self.shutter_open = True
        self.roi = (0, 0, self.optics.width, self.optics.height)
        self.last = None

    @staticmethod
    def _no_args(args: list[str]) -> None:
        expect_args(args, 0)

    def _set_exposure(self, args: list[str]) -> None:
        expect_args(args, 1)
        self.exposure_s = parse_number(args[0], "EXP", *EXPOSURE_RANGE_S, DEFAULT_EXPOSURE_S)

    def _set_gain(self, args: list[str]) -> None:
        expect_args(args, 1)
        self.gain = parse_number(args[0], "GAIN", *GAIN_RANGE, 1.0)

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
        expect_args(args, 4)
        values = []
        for name, text in zip(("x0", "y0", "width", "height"), args):
            if not text.lstrip("+").isdigit():
                raise ScpiError(-104, f"ROI {name} expects a non-negative integer, got {text!r}")
            values.append(int(text))
        x0, y0, w, h = values
        if w < 1 or h < 1 or x0 + w > self.optics.width or y0 + h > self.optics.height:
            raise ScpiError(-222, f"ROI {x0},{y0},{w},{h} outside the {self.optics.width}x{self.optics.height} sensor")
        self.roi = (x0, y0, w, h)

    def _acquire(self, args: list[str]) -> None:
        expect_args(args, 0)
        if self.fault:
            raise ScpiError(-200, "camera fault")
        t0 = self.clock.now()
        photons = self.scene(t0, self.exposure_s) if self.shutter_open else 0.0
        self.last = self.sensor.expose(photons, self.exposure_s, self.gain, self.rng)
        self.clock.wait_until(t0 + self.exposure_s + self.sensor.params.readout_s)

    def _need_frame(self) -> Exposure:
        if self.last is None:
            raise ScpiError(-221, "no frame acquired")
        return self.last

    def _roi_stat(self, args: list[str]) -> str:
        expect_args(args, 0)
        shot = self._need_frame()
        mean, std, n, sat = roi_statistics(shot.frame, shot.saturated, self.roi)
        return f"{mean:.4f},{std:.4f},{n},{sat}"

    def _frame(self, args: list[str]) -> bytes:
        expect_args(args, 0)
        shot = self._need_frame()
        return definite_length_block(shot.frame.astype("<u2").tobytes())

    def _info(self, args: list[str]) -> str:
        expect_args(args, 0)
        o = self.optics
        fields = (o.width, o.height, self.sensor.params.bits, o.pixel_pitch_um, o.focal_length_mm, o.distance_mm)
        return ",".join(format_number(v) for v in fields)

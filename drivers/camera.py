"""Driver for the rig's CCD camera (512 x 480 pixels, 12-bit ADC; SCPI over 115200 8N1).

Commands (docs/protocol.md): ``EXP``/``EXP?`` exposure [s], ``GAIN``/``GAIN?`` analog gain
factor (system gain K = K0 * factor [DN/e-]), ``SHUT OPEN|CLOSE``/``SHUT?``, ``ROI
x0,y0,w,h``/``ROI?`` [pixel], ``ACQ`` (one exposure), ``ROI:STAT?`` (mean, std, pixel count,
saturated count of the last frame inside the ROI), ``FRAME?`` (the last frame as an
IEEE 488.2 definite-length block of little-endian uint16, row-major), ``SENS:INFO?``
(width, height, bits, pixel pitch [um], focal length [mm], working distance [mm]),
``TEMP?``, ``ROI:DATA?`` (the ROI's pixels of the last frame as a block), ``*OPT?``
(installed options: ``MON`` when the lamp monitor is fitted) and ``MON?`` (the lamp
monitor reading integrated over the last exposure [V]).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CameraError, ProtocolError
from .scpi import ScpiInstrument

__all__ = ["Camera", "SensorInfo", "RoiStats", "Roi"]


@dataclass(frozen=True)
class SensorInfo:
    """Sensor and optics as reported by ``SENS:INFO?``.

    Attributes
    ----------
    width, height : int
        Frame size [pixel].
    bits : int
        ADC resolution [bit]; the largest digital number is ``2**bits - 1``.
    pixel_pitch_um : float
        Pixel pitch [um].
    focal_length_mm : float
        Lens focal length [mm].
    distance_mm : float
        Distance from the lens to the sample centre [mm].
    """

    width: int
    height: int
    bits: int
    pixel_pitch_um: float
    focal_length_mm: float
    distance_mm: float

    @property
    def max_dn(self) -> int:
        """Largest digital number of the ADC [DN]."""
        return 2**self.bits - 1

    @property
    def magnification(self) -> float:
        """Thin-lens lateral magnification f / (d - f) of the sample plane [-]."""
        return self.focal_length_mm / (self.distance_mm - self.focal_length_mm)

    @property
    def sample_mm_per_pixel(self) -> float:
        """Sample length imaged onto one pixel pitch, at normal view [mm/pixel]."""
        return self.pixel_pitch_um * 1e-3 / self.magnification

    @classmethod
    def parse(cls, reply: str) -> "SensorInfo":
        parts = reply.split(",")
        if len(parts) != 6:
            raise ValueError("expected 6 comma-separated fields")
        return cls(
            int(parts[0]), int(parts[1]), int(parts[2]),
            float(parts[3]), float(parts[4]), float(parts[5]),
        )


@dataclass(frozen=True)
class Roi:
    """A rectangular region of interest [pixel]: columns x0..x0+width-1, rows y0..y0+height-1."""

    x0: int
    y0: int
    width: int
    height: int

    @property
    def pixels(self) -> int:
        """Number of pixels in the region [-]."""
        return self.width * self.height

    def slices(self) -> tuple[slice, slice]:
        """``(rows, columns)`` slices selecting the region from a frame array."""
        return slice(self.y0, self.y0 + self.height), slice(self.x0, self.x0 + self.width)

    @classmethod
    def parse(cls, reply: str) -> "Roi":
        parts = [int(float(p)) for p in reply.split(",")]
        if len(parts) != 4:
            raise ValueError("expected 4 comma-separated integers")
        return cls(*parts)


@dataclass(frozen=True)
class RoiStats:
    """Statistics of the last frame inside the ROI (``ROI:STAT?``).

    Attributes
    ----------
    mean : float
        Mean digital number [DN].
    std : float
        Standard deviation over the ROI pixels (spatial: shot, read and fixed-pattern
        noise together) [DN].
    pixels : int
        Number of pixels in the ROI [-].
    saturated : int
        Pixels at the ADC maximum or full well [-].
    """

    mean: float
    std: float
    pixels: int
    saturated: int

    @classmethod
    def parse(cls, reply: str) -> "RoiStats":
        parts = reply.split(",")
        if len(parts) != 4:
            raise ValueError("expected '<mean>,<std>,<pixels>,<saturated>'")
        return cls(float(parts[0]), float(parts[1]), int(float(parts[2])), int(float(parts[3])))


class Camera(ScpiInstrument):
    """Client of the rig's CCD camera.

    Examples
    --------
    >>> cam = Camera.open("gonio-sim://camera?rig=lab")     # doctest: +SKIP
    >>> cam.set_exposure(0.02); cam.acquire()               # doctest: +SKIP
    >>> cam.roi_stats().mean                                # doctest: +SKIP
    1843.2
    """

    BAUDRATE = 115200
    DEVICE = "camera"
    ERROR = CameraError

    #: Readout time allowance added to the exposure when waiting for ``ACQ`` [s].
    READOUT_ALLOWANCE = 1.0

    def __init__(self, line, check_errors: bool = True):
        super().__init__(line, check_errors)
        self._info: SensorInfo | None = None
        self._exposure: float | None = None

    # -- sensor and optics ------------------------------------------------------------------
    def sensor_info(self) -> SensorInfo:
        """Sensor size, ADC depth and optics (``SENS:INFO?``; cached)."""
        if self._info is None:
            self._info = self.query("SENS:INFO?", SensorInfo.parse)
        return self._info

    def temperature(self) -> float:
        """Sensor temperature (``TEMP?``) [deg C]."""
        return self.query("TEMP?", float)

    def options(self) -> tuple[str, ...]:
        """Installed options (IEEE 488.2 ``*OPT?``; ``0`` means none), e.g. ``("MON",)``.

        A camera that does not implement ``*OPT?`` is taken to have no options (its error
        is drained from the queue).
        """
        try:
            reply = self.query("*OPT?", retries=0)
        except CameraError as error:
            if error.code != -113:
                raise
            return ()
        names = tuple(part.strip().upper() for part in reply.split(",") if part.strip())
        return () if names == ("0",) else names

    def simulated_time(self) -> float | None:
        """The emulator's simulated clock (``SIMulation:TIME?``) [s]; None for a real camera.

        The query is sent as ``SIM:TIME?;*OPC?``, so a camera without it still answers at
        once (``1``, with -113 queued and drained here) instead of letting the line time out.

        Examples
        --------
        >>> camera.simulated_time()     # doctest: +SKIP
        1311.6
        """
        reply = self.query("SIM:TIME?;*OPC?", retries=0)
        parts = reply.split(";")
        if len(parts) == 2:
            return float(parts[0])
        if parts != ["1"]:
            raise ProtocolError(f"camera: unexpected reply {reply!r} to 'SIM:TIME?;*OPC?'")
        for code, message in self.errors():
            if code != -113:
                raise self._error(code, message, "SIM:TIME?")
        return None

    def monitor(self) -> float:
        """Lamp monitor reading integrated over the last exposure (``MONitor?``) [V].

        The monitor photodiode looks at the lamp through a beam splitter and is triggered
        with every ``ACQ``, dark frames included (the shutter is in front of the camera,
        not of the monitor).
        """
        return self.query("MON?", float)

    # -- settings -----------------------------------------------------------------------------
    def exposure(self) -> float:
        """Exposure time (``EXP?``) [s]."""
        self._exposure = self.query("EXP?", float)
        return self._exposure

    def set_exposure(self, seconds: float, check: bool | None = None) -> None:
        """Set the exposure time (``EXP``) [s]; the camera checks the range (-222)."""
        self.write(f"EXP {float(seconds):.9g}", check)
        self._exposure = float(seconds)

    def gain(self) -> float:
        """Analog gain factor (``GAIN?``) [-]."""
        return self.query("GAIN?", float)

    def set_gain(self, factor: float, check: bool | None = None) -> None:
        """Set the analog gain factor (``GAIN``) [-]."""
        self.write(f"GAIN {float(factor):.9g}", check)

    def shutter_is_open(self) -> bool:
        """True if the shutter is open (``SHUT?``)."""
        reply = self.query("SHUT?", lambda r: r.strip().upper())
        if reply not in ("OPEN", "CLOSE", "CLOSED", "1", "0"):
            raise ProtocolError(f"camera: unexpected SHUT? reply {reply!r}")
        return reply in ("OPEN", "1")

    def open_shutter(self, check: bool | None = None) -> None:
        """Open the shutter (``SHUT OPEN``)."""
        self.write("SHUT OPEN", check)

    def close_shutter(self, check: bool | None = None) -> None:
        """Close the shutter for dark frames (``SHUT CLOSE``)."""
        self.write("SHUT CLOSE", check)

    def roi(self) -> Roi:
        """Region of interest (``ROI?``) [pixel]."""
        return self.query("ROI?", Roi.parse)

    def set_roi(self, roi: Roi, check: bool | None = None) -> None:
        """Set the region of interest (``ROI x0,y0,w,h``) [pixel]."""
        self.write(f"ROI {roi.x0},{roi.y0},{roi.width},{roi.height}", check)

    # -- acquisition --------------------------------------------------------------------------
    def acquire(self, timeout: float | None = None) -> None:
        """Take one exposure (``ACQ``) and wait until it is read out (``*OPC?``).

        Parameters
        ----------
        timeout : float, optional
            Longest wall-clock wait for the frame [s]; default: exposure + the line
            timeout + :attr:`READOUT_ALLOWANCE` (real-time mode takes that long).
        """
        self.write("ACQ", check=False)
        if timeout is None:
            exposure = self._exposure if self._exposure is not None else self.exposure()
            timeout = exposure + self.line.timeout + self.READOUT_ALLOWANCE
        self.operation_complete(timeout=timeout)
        if self.check_errors:
            self.raise_error("ACQ")

    def roi_stats(self) -> RoiStats:
        """Statistics of the last frame inside the ROI (``ROI:STAT?``)."""
        return self.query("ROI:STAT?", RoiStats.parse)

    def roi_frame(self, roi: Roi, timeout: float | None = None) -> np.ndarray:
        """The pixels of the last frame inside the current ROI (``ROI:DATA?``) [DN].

        ``roi`` is the region set with :meth:`set_roi` (it gives the array's shape); the
        block holds ``height x width`` little-endian uint16 values, row-major. Reading a
        window instead of the whole frame cuts the transfer time by the area ratio.
        """
        nbytes = roi.width * roi.height * 2
        if timeout is None:
            timeout = self.line.timeout + 2 * nbytes * 10 / self.BAUDRATE
        payload = self._read_block("ROI:DATA?", timeout)
        if len(payload) != nbytes:
            raise ProtocolError(f"camera: ROI:DATA? block has {len(payload)} bytes, expected {nbytes} "
                                f"({roi.height} x {roi.width} uint16)")
        return np.frombuffer(payload, dtype="<u2").reshape(roi.height, roi.width).copy()

    def _read_block(self, command: str, timeout: float) -> bytes:
        self.line.write(command)
        self.line.exchanges += 1
        try:
            return self.line.read_block(timeout=timeout, command=command)
        except Exception:
            if self.check_errors:
                self.raise_error(command)
            raise

    def frame(self, timeout: float | None = None) -> np.ndarray:
        """The last full frame (``FRAME?``) as a ``(height, width)`` uint16 array [DN].

        The timeout defaults to the line timeout plus twice the transfer time of the block
        at the line's baud rate (a real port needs ~43 s for 480 x 512 x 2 bytes).
        """
        info = self.sensor_info()
        nbytes = info.width * info.height * 2
        if timeout is None:
            timeout = self.line.timeout + 2 * nbytes * 10 / self.BAUDRATE
        payload = self._read_block("FRAME?", timeout)
        if len(payload) != nbytes:
            raise ProtocolError(
                f"camera: FRAME? block has {len(payload)} bytes, expected {nbytes} "
                f"({info.height} x {info.width} uint16)"
            )
        return np.frombuffer(payload, dtype="<u2").reshape(info.height, info.width).copy()

"""Exception hierarchy of the client drivers.

Every error a driver raises derives from :class:`DriverError`, so a caller can catch the
whole family at once; the subclasses tell *where* the failure happened:

``DriverError``
    ``TransportError``            the serial line itself failed (port vanished, I/O error)
        ``ResponseTimeout``       no complete reply within the timeout (also a ``TimeoutError``)
    ``ProtocolError``             a reply arrived but could not be parsed (garbled, wrong shape)
    ``DeviceError``               the instrument reported an error (code and message from it)
        ``StageError``            ESP300 error (``TB?``), with the axis for axis-specific codes
        ``CameraError``           camera SCPI error queue entry (``SYST:ERR?``)
        ``LampError``             lamp supply SCPI error queue entry, or a lamp fault
    ``MotionTimeout``             the stage did not report "motion done" in time
    ``PositionError``             the stage did not reach the commanded geometry, or its
                                  readback could not confirm it (after bounded retries)
    ``GeometryError``             a requested geometry refused before anything was sent
                                  (also a ``ValueError``: it is bad input)
    ``ExposureError``             automatic exposure could not reach a usable signal

The device's own error text is kept verbatim in :attr:`DeviceError.message` and appears in
``str(error)``.
"""
from __future__ import annotations

__all__ = [
    "DriverError",
    "TransportError",
    "ResponseTimeout",
    "ProtocolError",
    "DeviceError",
    "StageError",
    "CameraError",
    "LampError",
    "MotionTimeout",
    "GeometryError",
    "PositionError",
    "ExposureError",
]


class DriverError(Exception):
    """Base class of every error raised by the client drivers."""


class TransportError(DriverError):
    """The serial line failed: the port could not be opened, vanished, or an I/O error."""


class ResponseTimeout(TransportError, TimeoutError):
    """No complete reply line (or block) arrived within the timeout.

    Attributes
    ----------
    command : str
        The command whose reply was awaited.
    timeout : float
        The timeout that expired [s].
    partial : bytes
        Bytes received before the deadline (possibly empty).
    """

    def __init__(self, command: str, timeout: float, partial: bytes = b"", port: str = ""):
        self.command = command
        self.timeout = timeout
        self.partial = partial
        self.port = port
        where = f" on {port}" if port else ""
        got = f"; received {partial!r} so far" if partial else ""
        super().__init__(f"no reply to {command!r}{where} within {timeout:g} s{got}")


class ProtocolError(DriverError):
    """A reply arrived but does not have the documented shape."""


class DeviceError(DriverError):
    """The instrument reported an error.

    Attributes
    ----------
    device : str
        Which instrument ("stage", "camera", "lamp").
    code : int
        The instrument's error code.
    message : str
        The instrument's own error text.
    command : str
        The command after which the error was read (may be empty).
    """

    def __init__(self, device: str, code: int, message: str, command: str = ""):
        self.device = device
        self.code = int(code)
        self.message = message
        self.command = command
        after = f" after {command!r}" if command else ""
        super().__init__(f"{device} error {self.code}: {message}{after}")


class StageError(DeviceError):
    """ESP300 error as read with ``TB?``.

    Axis-specific codes have the form ``axis * 100 + n`` (ESP300 manual, error
    messages); :attr:`axis` is that axis (``None`` for general errors) and
    :attr:`axis_code` the two-digit ``n``.
    """

    def __init__(self, code: int, message: str, command: str = ""):
        super().__init__("stage", code, message, command)
        self.axis = self.code // 100 if self.code >= 100 else None
        self.axis_code = self.code % 100 if self.code >= 100 else None


class CameraError(DeviceError):
    """Camera error from its SCPI error queue (``SYST:ERR?``)."""

    def __init__(self, code: int, message: str, command: str = ""):
        super().__init__("camera", code, message, command)


class LampError(DeviceError):
    """Lamp power-supply error from its SCPI error queue, or a lamp fault."""

    def __init__(self, code: int, message: str, command: str = ""):
        super().__init__("lamp", code, message, command)


class MotionTimeout(DriverError, TimeoutError):
    """The stage did not report motion done (``MD?`` -> 1) within the allowed time."""


class PositionError(DriverError):
    """The stage did not reach the commanded geometry, or its readback could not confirm it.

    Raised by :meth:`drivers.rig.Rig.move_to` after its bounded retries; the message
    names each attempt's failure (limit stop, garbled reply, readback off target).
    """


class GeometryError(DriverError, ValueError):
    """A measurement geometry was refused before any command was sent."""


class ExposureError(DriverError):
    """Automatic exposure could not reach a usable signal (too dark or always saturated)."""

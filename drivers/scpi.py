"""Common client of SCPI-style (IEEE 488.2) instruments on a serial line.

Commands and replies end in LF. The common commands ``*IDN?``, ``*RST``, ``*CLS``,
``*OPC?`` and the error queue ``SYST:ERR?`` (replies ``0,"No error"`` or
``<code>,"<message>"``, oldest first) are wrapped here; the camera and lamp drivers add
their own commands.

IEEE 488.2 behaviour that shapes this client: a command that fails is not answered; the
error is queued. So :meth:`ScpiInstrument.write` reads ``SYST:ERR?`` after each command
(unless ``check=False``), and a query that gets no reply reads the queue before deciding
whether the silence was the instrument's refusal (raise its error) or a transient fault
(retry, up to the line's retry count).
"""
from __future__ import annotations

from typing import Callable, TypeVar

from .errors import DeviceError, ProtocolError
from .serial_line import SerialLine

__all__ = ["ScpiInstrument", "parse_scpi_error"]

T = TypeVar("T")


def parse_scpi_error(reply: str) -> tuple[int, str]:
    """Parse a ``SYST:ERR?`` reply ``<code>,"<message>"`` into ``(code, message)``.

    Examples
    --------
    >>> parse_scpi_error('-222,"Data out of range"')
    (-222, 'Data out of range')
    >>> parse_scpi_error('0,"No error"')
    (0, 'No error')
    """
    code_text, sep, message = reply.partition(",")
    if not sep:
        raise ProtocolError(f'SYST:ERR? reply {reply!r} is not <code>,"<message>"')
    try:
        code = int(code_text.strip())
    except ValueError as exc:
        raise ProtocolError(f"SYST:ERR? reply {reply!r} has a non-integer code") from exc
    return code, message.strip().strip('"')


class ScpiInstrument:
    """Base class of the SCPI instrument drivers.

    Parameters
    ----------
    line : SerialLine
        An open line with LF terminators (see :meth:`open`).
    check_errors : bool
        Read the error queue after every command and raise on an error.
    """

    BAUDRATE = 9600
    DEVICE = "instrument"
    ERROR = DeviceError

    def __init__(self, line: SerialLine, check_errors: bool = True):
        self.line = line
        self.check_errors = bool(check_errors)

    @classmethod
    def open(cls, url: str, *, timeout: float = 1.0, retries: int = 1, **kwargs):
        """Open the instrument at a port path or pyserial URL (8N1, LF terminators)."""
        line = SerialLine(
            url,
            baudrate=cls.BAUDRATE,
            write_termination="\n",
            read_termination="\n",
            timeout=timeout,
            retries=retries,
            name=f"{cls.DEVICE} ({url})",
            resync=("*IDN?", lambda reply: reply.count(",") == 3),  # IEEE 488.2 10.14: four fields
        )
        return cls(line, **kwargs)

    def close(self) -> None:
        """Close the serial line."""
        self.line.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _error(self, code: int, message: str, command: str) -> DeviceError:
        if self.ERROR is DeviceError:
            return DeviceError(self.DEVICE, code, message, command)
        return self.ERROR(code, message, command)

    # -- error queue --------------------------------------------------------------------------
    def read_error(self) -> tuple[int, str]:
        """Pop the oldest entry of the error queue: ``(code, message)``; code 0: empty."""
        return self.line.query("SYST:ERR?", parse=parse_scpi_error)

    def errors(self, limit: int = 40) -> list[tuple[int, str]]:
        """Drain the error queue; return its entries, oldest first (at most ``limit``)."""
        found = []
        for _ in range(limit):
            code, message = self.read_error()
            if code == 0:
                break
            found.append((code, message))
        return found

    def raise_error(self, command: str = "") -> None:
        """Raise the device's error for the oldest queued entry, if any.

        The remaining entries are drained and attached as ``error.more``.
        """
        code, message = self.read_error()
        if code != 0:
            error = self._error(code, message, command)
            error.more = self.errors()
            raise error

    # -- exchange -----------------------------------------------------------------------------
    def write(self, command: str, check: bool | None = None) -> None:
        """Send a command (no reply); then check the error queue.

        Raises
        ------
        DeviceError
            The instrument's error (its subclass for this instrument) if one was queued.
        """
        self.line.write(command)
        self.line.exchanges += 1
        if self.check_errors if check is None else check:
            self.raise_error(command)

    def query(
        self,
        command: str,
        parse: Callable[[str], T] = str,
        *,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> T:
        """Send a query and return its parsed reply.

        A query that gets no reply is followed by ``SYST:ERR?``: a queued error is raised as
        the instrument's error; otherwise the query is retried (bounded), and finally a
        :class:`~drivers.errors.ResponseTimeout` is raised.
        """

        def recover(_exc) -> None:
            self.raise_error(command)

        return self.line.query(command, parse=parse, timeout=timeout, retries=retries, recover=recover)

    # -- IEEE 488.2 common commands -----------------------------------------------------------
    def identity(self) -> str:
        """``*IDN?``: manufacturer, model, serial number, firmware."""
        return self.query("*IDN?")

    def reset(self) -> None:
        """``*RST``: return to the power-on settings."""
        self.write("*RST")

    def clear_status(self) -> None:
        """``*CLS``: clear the error queue and status."""
        self.write("*CLS", check=False)

    def operation_complete(self, timeout: float | None = None) -> bool:
        """``*OPC?``: wait until pending operations finish (reply ``1``)."""
        return self.query("*OPC?", lambda r: int(r) == 1, timeout=timeout, retries=0)

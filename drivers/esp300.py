"""Driver for a Newport ESP300/ESP301 motion controller (RS-232 ASCII dialect).

The command syntax follows the vendor's user manual (Newport, "ESP300 Motion
Controller/Driver User's Manual", section 3 "Remote Mode": command syntax ``xxCCnn`` with
axis prefix ``xx``, command ``CC`` and parameter ``nn``; ``;`` joins commands on one line;
error codes read with ``TE?``/``TB?``, axis-specific codes being ``axis*100 + n``). Line
settings: 19200 baud, 8N1; commands end in CR, replies in CR LF.

Only the subset the gonio rig needs is wrapped: absolute/relative moves, position and
motion-done queries, motor on/off, homing, software travel limits, units, encoder
resolution, velocity, acceleration, stop, identity and the error queue. :meth:`ESP300.send` and
:meth:`ESP300.ask` pass any other command through.

A command that the controller rejects produces no reply; the error waits in the
controller's queue. The driver therefore reads ``TB?`` after every command (unless
``check=False``) and after a query that timed out, and raises
:class:`~drivers.errors.StageError` with the controller's code and message.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable, TypeVar

from .errors import MotionTimeout, ProtocolError, ResponseTimeout, StageError
from .serial_line import SerialLine

__all__ = ["ESP300", "ErrorEntry", "UNIT_CODES"]

T = TypeVar("T")

#: ``SN`` unit codes of the ESP300 manual (command SN): code -> unit name.
UNIT_CODES = {
    0: "encoder count",
    1: "motor step",
    2: "millimeter",
    3: "micrometer",
    4: "inch",
    5: "milli-inch",
    6: "micro-inch",
    7: "degree",
    8: "gradian",
    9: "radian",
    10: "milliradian",
    11: "microradian",
}

#: Code of "NO ERROR DETECTED" in ``TE?``/``TB?``.
NO_ERROR = 0


@dataclass(frozen=True)
class ErrorEntry:
    """One entry of the controller's error buffer as returned by ``TB?``.

    Attributes
    ----------
    code : int
        Error code (0: no error; ``axis*100 + n`` for axis-specific errors).
    timestamp : int
        Controller timestamp of the error [controller ticks].
    message : str
        The controller's message text.
    """

    code: int
    timestamp: int
    message: str


def parse_error_entry(reply: str) -> ErrorEntry:
    """Parse a ``TB?`` reply ``"<code>, <timestamp>, <MESSAGE>"``.

    Examples
    --------
    >>> parse_error_entry("0, 451322, NO ERROR DETECTED")
    ErrorEntry(code=0, timestamp=451322, message='NO ERROR DETECTED')
    """
    parts = [p.strip() for p in reply.split(",", 2)]
    if len(parts) != 3:
        raise ProtocolError(f"TB? reply {reply!r} is not '<code>, <timestamp>, <message>'")
    try:
        return ErrorEntry(int(parts[0]), int(float(parts[1])), parts[2])
    except ValueError as exc:
        raise ProtocolError(f"TB? reply {reply!r} has a non-numeric code or timestamp") from exc


def _parse_flag(reply: str) -> bool:
    value = int(float(reply))
    if value not in (0, 1):
        raise ValueError(f"expected 0 or 1, got {reply!r}")
    return bool(value)


class ESP300:
    """Client of an ESP300/ESP301 motion controller.

    Parameters
    ----------
    line : SerialLine
        An open line with CR command and CR LF reply terminators (see :meth:`open`).
    axes : iterable of int
        Axis numbers present (for argument checks) [-].
    check_errors : bool
        Read ``TB?`` after every command and raise on an error (recommended).

    Examples
    --------
    >>> stage = ESP300.open("/dev/ttyUSB0")          # doctest: +SKIP
    >>> stage.move_absolute(2, 30.0)                 # doctest: +SKIP
    >>> stage.position(2)                            # doctest: +SKIP
    30.0
    """

    BAUDRATE = 19200
    WRITE_TERMINATION = "\r"
    READ_TERMINATION = "\r\n"

    def __init__(self, line: SerialLine, axes: Iterable[int] = (1, 2, 3), check_errors: bool = True):
        self.line = line
        self.axes = tuple(int(a) for a in axes)
        self.check_errors = bool(check_errors)

    @classmethod
    def open(cls, url: str, *, timeout: float = 1.0, retries: int = 1, **kwargs) -> "ESP300":
        """Open the controller at a port path or pyserial URL (19200 8N1, CR / CR LF)."""
        line = SerialLine(
            url,
            baudrate=cls.BAUDRATE,
            write_termination=cls.WRITE_TERMINATION,
            read_termination=cls.READ_TERMINATION,
            timeout=timeout,
            retries=retries,
            name=f"stage ({url})",
            resync=("VE?", lambda reply: reply.startswith("ESP300")),  # the version query marks the line's step
        )
        return cls(line, **kwargs)

    def close(self) -> None:
        """Close the serial line (motors are left as they are)."""
        self.line.close()

    def __enter__(self) -> "ESP300":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- generic exchange -----------------------------------------------------------------
    def _axis(self, axis: int) -> int:
        if int(axis) not in self.axes:
            raise ValueError(f"axis={axis!r} is not one of the controller's axes {self.axes}")
        return int(axis)

    def read_error(self) -> ErrorEntry:
        """Pop the oldest error from the controller's buffer (``TB?``)."""
        return self.line.query("TB?", parse=parse_error_entry)

    def error_code(self) -> int:
        """Pop the oldest error code (``TE?``) [-]."""
        return self.line.query("TE?", parse=lambda r: int(float(r)))

    def errors(self, limit: int = 20) -> list[ErrorEntry]:
        """Drain the error buffer; return the errors, oldest first (at most ``limit``)."""
        found = []
        for _ in range(limit):
            entry = self.read_error()
            if entry.code == NO_ERROR:
                break
            found.append(entry)
        return found

    def raise_error(self, command: str = "") -> None:
        """Raise :class:`StageError` for the oldest queued error, if there is one.

        Further queued errors are drained and attached as ``error.more``.
        """
        entry = self.read_error()
        if entry.code != NO_ERROR:
            error = StageError(entry.code, entry.message, command)
            error.more = self.errors()
            raise error

    def send(self, command: str, check: bool | None = None) -> None:
        """Send a command that has no reply; check the error buffer afterwards.

        Raises
        ------
        StageError
            If the controller reports an error (when checking).
        """
        self.line.write(command)
        self.line.exchanges += 1
        if self.check_errors if check is None else check:
            self.raise_error(command)

    def ask(
        self,
        command: str,
        parse: Callable[[str], T] = str,
        *,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> T:
        """Send a query and return its parsed reply.

        If no reply arrives, the error buffer is read: a rejected query raises
        :class:`StageError` with the controller's message instead of a timeout.
        """

        def recover(_exc) -> None:
            self.raise_error(command)

        return self.line.query(command, parse=parse, timeout=timeout, retries=retries, recover=recover)

    # -- identity and configuration ---------------------------------------------------------
    def identity(self) -> str:
        """Controller model and firmware version (``VE?``)."""
        return self.ask("VE?")

    def units(self, axis: int) -> str:
        """Unit of an axis (``xxSN?``), as a name from :data:`UNIT_CODES`."""
        code = self.ask(f"{self._axis(axis)}SN?", lambda r: int(float(r)))
        if code not in UNIT_CODES:
            raise ProtocolError(f"stage: unknown unit code {code} for axis {axis}")
        return UNIT_CODES[code]

    def set_units(self, axis: int, unit: str) -> None:
        """Set the unit of an axis (``xxSNnn``)."""
        codes = {name: code for code, name in UNIT_CODES.items()}
        if unit not in codes:
            raise ValueError(f"unit={unit!r} is not one of {sorted(codes)}")
        self.send(f"{self._axis(axis)}SN{codes[unit]}")

    def encoder_resolution(self, axis: int) -> float:
        """Encoder resolution of an axis (``xxSU?``): one encoder count [axis units].

        Parameters
        ----------
        axis : int
            Axis number.

        Returns
        -------
        float
            Distance of one encoder count, in the axis's units (``xxSN?``) [axis units];
            it is the step of the positions :meth:`position` reads back.

        Raises
        ------
        ProtocolError
            If the controller replies a resolution that is not a positive number.

        Notes
        -----
        The ESP300 manual's ``SU`` command (section 3, "Remote Mode") sets and reads the
        encoder resolution; the driver only reads it, since the resolution is a
        property of the stage's encoder.

        Examples
        --------
        >>> stage.encoder_resolution(1)                  # doctest: +SKIP
        0.001
        """
        value = self.ask(f"{self._axis(axis)}SU?", float)
        if not (value > 0 and math.isfinite(value)):
            raise ProtocolError(f"stage: encoder resolution {value!r} of axis {axis} is not a positive number")
        return value

    def travel_limits(self, axis: int) -> tuple[float, float]:
        """Software travel limits (left ``xxSL?``, right ``xxSR?``) [axis units]."""
        a = self._axis(axis)
        return self.ask(f"{a}SL?", float), self.ask(f"{a}SR?", float)

    def set_travel_limits(self, axis: int, left: float, right: float) -> None:
        """Set the software travel limits (``xxSLnn``, ``xxSRnn``) [axis units]."""
        if not left < right:
            raise ValueError(f"left={left!r} must be < right={right!r}")
        a = self._axis(axis)
        self.send(f"{a}SL{left:.6g}")
        self.send(f"{a}SR{right:.6g}")

    def velocity(self, axis: int) -> float:
        """Programmed velocity (``xxVA?``) [units/s]."""
        return self.ask(f"{self._axis(axis)}VA?", float)

    def set_velocity(self, axis: int, value: float) -> None:
        """Set the velocity (``xxVAnn``) [units/s]; the controller checks the range."""
        self.send(f"{self._axis(axis)}VA{value:.6g}")

    def acceleration(self, axis: int) -> float:
        """Programmed acceleration (``xxAC?``) [units/s^2]."""
        return self.ask(f"{self._axis(axis)}AC?", float)

    def set_acceleration(self, axis: int, value: float) -> None:
        """Set the acceleration (``xxACnn``) [units/s^2]."""
        self.send(f"{self._axis(axis)}AC{value:.6g}")

    def deceleration(self, axis: int) -> float:
        """Programmed deceleration of moves and stops (``xxAG?``) [units/s^2]."""
        return self.ask(f"{self._axis(axis)}AG?", float)

    def set_deceleration(self, axis: int, value: float) -> None:
        """Set the deceleration (``xxAGnn``) [units/s^2]."""
        self.send(f"{self._axis(axis)}AG{value:.6g}")

    # -- motors -----------------------------------------------------------------------------
    def motor_on(self, axis: int) -> None:
        """Power the motor of an axis (``xxMO``)."""
        self.send(f"{self._axis(axis)}MO")

    def motor_off(self, axis: int) -> None:
        """Switch the motor of an axis off (``xxMF``)."""
        self.send(f"{self._axis(axis)}MF")

    def motor_is_on(self, axis: int) -> bool:
        """True if the motor is powered (``xxMO?``)."""
        return self.ask(f"{self._axis(axis)}MO?", _parse_flag)

    # -- motion -----------------------------------------------------------------------------
    def position(self, axis: int) -> float:
        """Actual position (``xxTP``) [axis units]."""
        return self.ask(f"{self._axis(axis)}TP", float)

    def positions(self, axes: Iterable[int] | None = None) -> dict[int, float]:
        """Actual positions of several axes with one command line (``1TP;2TP;...``).

        Raises
        ------
        ProtocolError
            If a reply is not a finite number (a garbled line); the line is marked out of
            step so that no late reply is taken for the answer to a later question.
        StageError
            If the replies do not come and the controller reports why.
        """
        axes = [self._axis(a) for a in (self.axes if axes is None else axes)]
        command = ";".join(f"{a}TP" for a in axes)
        replies: list[str] = []
        with self.line._lock:
            self.line.write(command)
            self.line.exchanges += 1
            try:
                replies = [self.line.read_line(command=command) for _ in axes]
                values = [float(r) for r in replies]
            except ValueError as exc:
                self.line.mark_out_of_step()
                raise ProtocolError(f"{self.line.name}: unexpected replies {replies!r} to {command!r}") from exc
            except ResponseTimeout:
                self.raise_error(command)
                raise
        if not all(math.isfinite(v) for v in values):
            raise ProtocolError(f"{self.line.name}: non-finite position in {replies!r} to {command!r}")
        return dict(zip(axes, values))

    def desired_position(self, axis: int) -> float:
        """Target of the current or last move (``xxDP?``) [axis units]."""
        return self.ask(f"{self._axis(axis)}DP?", float)

    def motion_done(self, axis: int) -> bool:
        """True when the axis is stopped (``xxMD?`` -> 1)."""
        return self.ask(f"{self._axis(axis)}MD?", _parse_flag)

    def move_absolute(self, axis: int, position: float, wait: bool = True, timeout: float = 300.0) -> None:
        """Move an axis to ``position`` (``xxPAnn``) [axis units].

        A move the controller refuses (travel limit, separation rule, motor off) raises
        :class:`StageError` and leaves the axis where it was.
        """
        a = self._axis(axis)
        self.send(f"{a}PA{position:.6f}")
        if wait:
            self.wait_motion_done([a], timeout=timeout)

    def move_relative(self, axis: int, distance: float, wait: bool = True, timeout: float = 300.0) -> None:
        """Move an axis by ``distance`` (``xxPRnn``) [axis units]."""
        a = self._axis(axis)
        self.send(f"{a}PR{distance:.6f}")
        if wait:
            self.wait_motion_done([a], timeout=timeout)

    def home(self, axis: int, mode: int | None = None, wait: bool = True, timeout: float = 300.0) -> None:
        """Search the home position of an axis (``xxOR`` or ``xxORnn``)."""
        a = self._axis(axis)
        self.send(f"{a}OR" if mode is None else f"{a}OR{int(mode)}")
        if wait:
            self.wait_motion_done([a], timeout=timeout)

    def wait(self, seconds: float, axis: int | None = None, timeout: float | None = None) -> None:
        """Wait for the axes to stop and then ``seconds`` more, in the controller's time.

        Sends ``WSnn`` (``xxWSnn`` for one axis) followed by an ``MD?`` query, whose reply
        comes only after the wait (commands are processed in order). On the emulator in
        fast mode this advances the simulated clock at once; on hardware it takes
        ``seconds``.

        Parameters
        ----------
        seconds : float
            Extra delay after the stop [s], >= 0.
        axis : int, optional
            Axis to wait for (default: all).
        timeout : float, optional
            Longest wall-clock wait [s] (default: ``seconds`` + 5 % + the line
            timeout; a move still in progress adds its remaining time, so pass a larger
            timeout when waiting for a long move in real time).
        """
        if not seconds >= 0:
            raise ValueError(f"seconds={seconds!r} must be >= 0")
        prefix = "" if axis is None else str(self._axis(axis))
        self.send(f"{prefix}WS{round(seconds * 1000)}", check=False)
        if timeout is None:
            timeout = 1.05 * seconds + self.line.timeout
        probe = self.axes[0] if axis is None else self._axis(axis)
        self.ask(f"{probe}MD?", _parse_flag, timeout=timeout, retries=0)
        if self.check_errors:
            self.raise_error(f"{prefix}WS")

    def stop(self, axis: int | None = None) -> None:
        """Stop one axis (``xxST``) or all axes (``ST``)."""
        self.send("ST" if axis is None else f"{self._axis(axis)}ST")

    def wait_motion_done(self, axes: Iterable[int] | None = None, timeout: float = 300.0) -> None:
        """Wait until the axes have stopped, then check the error buffer.

        Sends ``xxWS`` for each axis followed by one ``xxMD?``: the controller holds the
        query until the motion ends (commands are processed in order), so one exchange
        replaces polling. On the emulator in fast mode the simulated clock jumps to the
        end of the move; on hardware the reply comes when the axes stop.

        Parameters
        ----------
        axes : iterable of int, optional
            Axes to wait for (default: all).
        timeout : float
            Longest wall-clock wait [s].

        Raises
        ------
        MotionTimeout
            If no reply came within ``timeout`` or an axis still reports motion.
        StageError
            If the controller queued an error during the motion (e.g. a limit was hit).
        """
        axes = [self._axis(a) for a in (self.axes if axes is None else axes)]
        self.send(";".join(f"{a}WS" for a in axes), check=False)
        try:
            done = self.ask(f"{axes[-1]}MD?", _parse_flag, timeout=timeout, retries=0)
        except ResponseTimeout as exc:
            raise MotionTimeout(f"stage axes {axes} did not stop within {timeout:g} s") from exc
        if not done:
            raise MotionTimeout(f"stage axis {axes[-1]} still moving after WS")
        if self.check_errors:
            self.raise_error("WS")

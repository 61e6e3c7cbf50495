"""Line-oriented request/response layer over a pyserial port.

:class:`SerialLine` opens any port path or pyserial URL (``/dev/ttyUSB0``, a pty path,
``socket://127.0.0.1:PORT``, ``loop://``, ``gonio-sim://camera?rig=NAME``) with
:func:`serial.serial_for_url`, writes terminated command lines, and reads terminated reply
lines and IEEE 488.2 definite-length blocks against a *total* deadline, so that no call can
hang: a missing reply is a :class:`~drivers.errors.ResponseTimeout`, a vanished port a
:class:`~drivers.errors.TransportError`.

After a timeout the line is marked out of step: before the next command, whatever arrived
late is discarded so that a late reply can never be taken for the answer to a later
question. Queries may be retried a bounded number of times on transient failures
(timeouts, garbled replies); an optional ``recover`` hook runs before each retry (the SCPI
drivers use it to read the error queue, so a query the device rejected is reported as the
device's error instead of being retried).
"""
from __future__ import annotations

import collections
import logging
import select
import socket
import threading
import time
from typing import Callable, TypeVar

import serial

from .errors import DriverError, ProtocolError, ResponseTimeout, TransportError

__all__ = ["SerialLine"]

_log = logging.getLogger(__name__)
T = TypeVar("T")

#: Longest a single blocking read waits before the total deadline is checked again [s].
_POLL_INTERVAL = 0.05


def _tcp_socket(port) -> socket.socket | None:
    """The TCP socket of a pyserial ``socket://`` port, None for any other port."""
    sock = getattr(port, "_socket", None)
    if isinstance(sock, socket.socket) and sock.family in (socket.AF_INET, socket.AF_INET6):
        return sock
    return None


def _send_without_delay(port) -> None:
    """Switch Nagle's algorithm off on a TCP port (pyserial ``socket://``): send each line at once.

    Without ``TCP_NODELAY`` a command that gets no reply followed by a query waits for the
    acknowledgement of the first segment, up to the peer's delayed-ACK time (40 ms on
    Linux).  Ports that are not TCP sockets are left alone.
    """
    sock = _tcp_socket(port)
    if sock is not None:
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError as exc:  # the line still works, only slower
            _log.debug("cannot set TCP_NODELAY: %s", exc)


#: The marker query of a resynchronisation waits this many line timeouts, at least
#: RESYNC_TIMEOUT_MIN [s]: its reply queues behind the late one.
RESYNC_TIMEOUT_FACTOR = 3.0
RESYNC_TIMEOUT_MIN = 1.0

#: Why a network port's connection ends under a controller, most often.
_CLOSED_BY_PEER = ("the connection was closed by the peer (an instrument on a network port serves one controller "
                   "at a time: is another program connected to it?)")


class SerialLine:
    """A serial line carrying terminated ASCII commands and replies.

    Parameters
    ----------
    url : str
        Port path or pyserial URL, opened with :func:`serial.serial_for_url`.
    baudrate : int
        Line speed [baud]; 8 data bits, no parity, 1 stop bit.
    write_termination : str
        Appended to every command (``"\\r"`` for the ESP300, ``"\\n"`` for SCPI).
    read_termination : str
        Ends every reply line (``"\\r\\n"`` for the ESP300, ``"\\n"`` for SCPI). Stripped
        from the returned text, together with surrounding whitespace.
    timeout : float
        Default total time allowed for one reply [s]; > 0.
    retries : int
        Default number of extra attempts of a query after a transient failure; >= 0.
    name : str, optional
        Name used in messages (default: the URL).
    encoding : str
        Text encoding of commands and replies.
    resync : (str, callable), optional
        A marker query without side effects and a test its reply passes (the ESP300's
        ``VE?``, SCPI's ``*IDN?``). After a timeout or a reply that did not parse, the
        line is out of step: a reply may still be on its way and would be read as the
        answer to the next command. Before the next command the marker is sent and every
        line up to its reply is discarded (the instrument answers in order), so that one
        late reply costs one exchange, not the run. Without it, only what has already
        arrived is discarded.
    **port_options
        Passed on to :func:`serial.serial_for_url` (e.g. ``rtscts``). ``exclusive``
        defaults to True: a local serial port (a device or the emulator's pseudo-terminal)
        is locked while it is open, and a second program that opens it is refused (one
        controller per instrument); pyserial ignores it for network ports, where the
        emulator itself serves one client at a time.

    Raises
    ------
    ValueError
        If ``timeout`` <= 0 or ``retries`` < 0.
    TransportError
        If the port cannot be opened.

    Examples
    --------
    >>> line = SerialLine("loop://", baudrate=9600, timeout=0.2)
    >>> line.write("hello")
    >>> line.read_line()
    'hello'
    >>> line.close()
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int,
        write_termination: str = "\n",
        read_termination: str = "\n",
        timeout: float = 1.0,
        retries: int = 1,
        name: str | None = None,
        encoding: str = "ascii",
        resync: tuple[str, Callable[[str], bool]] | None = None,
        **port_options,
    ) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout={timeout!r} s is invalid; it must be > 0")
        if int(retries) < 0:
            raise ValueError(f"retries={retries!r} is invalid; it must be >= 0")
        self.url = url
        self.resync = resync
        self.name = name or url
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.encoding = encoding
        self.write_termination = write_termination.encode(encoding)
        self.read_termination = read_termination.encode(encoding)
        # Accept a bare final LF (or CR) even when CR LF is the documented terminator:
        # the last byte of the terminator delimits lines; the rest is stripped.
        self._delimiter = self.read_termination[-1:]
        self._buffer = bytearray()
        self._out_of_step = False
        self._lock = threading.RLock()
        self.transcript: collections.deque[tuple[float, str, bytes]] = collections.deque(
            maxlen=200
        )
        self.exchanges = 0
        try:
            port_options.setdefault("exclusive", True)
            self._port = serial.serial_for_url(
                url,
                baudrate=baudrate,
                bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE,
                stopbits=serial.STOPBITS_ONE,
                timeout=min(_POLL_INTERVAL, self.timeout),
                write_timeout=self.timeout,
                **port_options,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            held = " (another program holds the port: one controller per instrument)" if "lock" in str(exc) else ""
            raise TransportError(f"cannot open {self.name}: {exc}{held}") from exc
        _send_without_delay(self._port)
        #: The TCP socket of a ``socket://`` port (read directly, see :meth:`_receive`), else None.
        self._socket = _tcp_socket(self._port)

    # -- context management -------------------------------------------------------------
    def __enter__(self) -> "SerialLine":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return f"SerialLine({self.url!r}, {state})"

    @property
    def is_open(self) -> bool:
        """True while the port is open."""
        port = getattr(self, "_port", None)
        return bool(port is not None and port.is_open)

    def close(self) -> None:
        """Close the port (idempotent)."""
        port = getattr(self, "_port", None)
        if port is not None and port.is_open:
            try:
                port.close()
            except (serial.SerialException, OSError):  # closing a dead port is not an error
                pass

    # -- low level ----------------------------------------------------------------------
    def _check_open(self) -> None:
        if not self.is_open:
            raise TransportError(f"{self.name} is closed")

    def discard_input(self) -> bytes:
        """Drop every byte already received or buffered; return what was dropped."""
        with self._lock:
            self._check_open()
            dropped = bytes(self._buffer)
            self._buffer.clear()
            try:
                waiting = self._port.in_waiting
                if waiting:
                    dropped += self._port.read(waiting)
                self._port.reset_input_buffer()
            except (serial.SerialException, OSError) as exc:
                raise TransportError(f"{self.name}: {exc}") from exc
            if dropped:
                _log.debug("%s: discarded %r", self.name, dropped)
            self._out_of_step = False
            return dropped

    def _resynchronise(self) -> None:
        """Send the marker query and discard every line before its reply (``resync``).

        The marker's reply may queue behind the late one, so it is given
        :data:`RESYNC_TIMEOUT_FACTOR` times the line's timeout, at least
        :data:`RESYNC_TIMEOUT_MIN`.

        Raises
        ------
        ResponseTimeout
            The marker's reply did not come in that time: the line stays out of step.
        """
        marker, is_reply = self.resync
        self._port.write(marker.encode(self.encoding) + self.write_termination)
        self.transcript.append((time.monotonic(), ">", marker.encode(self.encoding)))
        deadline = time.monotonic() + max(RESYNC_TIMEOUT_FACTOR * self.timeout, RESYNC_TIMEOUT_MIN)
        while True:
            line = self.read_line(timeout=max(deadline - time.monotonic(), 1e-3), command=marker)
            if is_reply(line):
                return
            _log.debug("%s: resynchronising, discarded the late line %r", self.name, line)

    def mark_out_of_step(self) -> None:
        """Declare the line out of step (e.g. a reply did not parse): whatever is still
        arriving is discarded before the next command is sent."""
        self._out_of_step = True

    def write(self, command: str) -> None:
        """Send one command line (the write terminator is appended).

        Raises
        ------
        ValueError
            If the command contains a line terminator (it would split into two commands).
        TransportError
            If the port is closed or the write fails or times out.
        """
        if "\n" in command or "\r" in command:
            raise ValueError(f"command={command!r} must not contain CR or LF")
        data = command.encode(self.encoding) + self.write_termination
        with self._lock:
            self._check_open()
            if self._out_of_step:
                self.discard_input()
                if self.resync is not None:
                    self._resynchronise()
            try:
                self._port.write(data)
            except serial.SerialTimeoutException as exc:
                raise TransportError(f"{self.name}: write of {command!r} timed out") from exc
            except (serial.SerialException, OSError) as exc:
                raise TransportError(f"{self.name}: cannot write {command!r}: {exc}") from exc
            self.transcript.append((time.monotonic(), ">", data))

    def _fill(self, deadline: float, command: str) -> None:
        """Read at least one more byte into the buffer, or raise at the deadline."""
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            self._out_of_step = True
            raise ResponseTimeout(command, self._last_timeout, bytes(self._buffer), self.name)
        try:
            if self._socket is not None:
                chunk = self._receive(min(_POLL_INTERVAL, remaining))
            else:
                chunk = self._port.read(max(1, self._port.in_waiting))
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            # TypeError/AttributeError: pyserial's posix read on a port closed under it.
            self._out_of_step = True
            raise TransportError(f"{self.name}: read failed: {exc}") from exc
        if chunk:
            self._buffer += chunk

    def _receive(self, wait: float) -> bytes:
        """Whatever a TCP port has received, waiting at most ``wait`` [s] for the first byte.

        pyserial's ``socket://`` port reports at most one byte waiting and so reads a reply
        one byte (and two system calls) at a time; the socket itself hands over everything
        that has arrived in one call.

        Raises
        ------
        serial.SerialException
            If the peer closed the connection.
        """
        ready, _, _ = select.select([self._socket], [], [], wait)
        if not ready:
            return b""
        try:
            chunk = self._socket.recv(65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except ConnectionResetError:
            chunk = b""
        if not chunk:
            raise serial.SerialException(_CLOSED_BY_PEER)
        return chunk

    def read_line(self, timeout: float | None = None, command: str = "") -> str:
        """Return the next reply line, without its terminator and surrounding blanks.

        Raises
        ------
        ResponseTimeout
            If no complete line arrives within ``timeout`` [s] (default: the line's).
        ProtocolError
            If the line cannot be decoded.
        """
        timeout = self.timeout if timeout is None else float(timeout)
        self._last_timeout = timeout
        deadline = time.monotonic() + timeout
        with self._lock:
            self._check_open()
            while True:
                end = self._buffer.find(self._delimiter)
                if end >= 0:
                    raw = bytes(self._buffer[: end + 1])
                    del self._buffer[: end + 1]
                    break
                self._fill(deadline, command)
            self.transcript.append((time.monotonic(), "<", raw))
        try:
            text = raw.decode(self.encoding)
        except UnicodeDecodeError as exc:
            raise ProtocolError(f"{self.name}: undecodable reply {raw!r} to {command!r}") from exc
        return text.strip()

    def read_exact(self, size: int, timeout: float | None = None, command: str = "") -> bytes:
        """Return exactly ``size`` bytes, or raise :class:`ResponseTimeout`."""
        timeout = self.timeout if timeout is None else float(timeout)
        self._last_timeout = timeout
        deadline = time.monotonic() + timeout
        with self._lock:
            self._check_open()
            while len(self._buffer) < size:
                self._fill(deadline, command)
            data = bytes(self._buffer[:size])
            del self._buffer[:size]
        return data

    def read_block(self, timeout: float | None = None, command: str = "") -> bytes:
        """Read an IEEE 488.2 definite-length block ``#<d><len><bytes>`` and its terminator.

        Raises
        ------
        ProtocolError
            If the header is malformed (the rest of the input is then discarded).
        ResponseTimeout
            If the block does not arrive completely within ``timeout`` [s].
        """
        timeout = self.timeout if timeout is None else float(timeout)
        deadline = time.monotonic() + timeout
        with self._lock:
            head = self.read_exact(2, timeout, command)
            if head[:1] != b"#" or not head[1:2].isdigit() or head[1:2] == b"0":
                self._out_of_step = True
                raise ProtocolError(
                    f"{self.name}: reply to {command!r} is not a definite-length block "
                    f"(starts with {head!r})"
                )
            ndigits = int(head[1:2])
            digits = self.read_exact(ndigits, max(deadline - time.monotonic(), 1e-3), command)
            if not digits.isdigit():
                self._out_of_step = True
                raise ProtocolError(f"{self.name}: bad block length {digits!r} in reply to {command!r}")
            size = int(digits)
            payload = self.read_exact(size, max(deadline - time.monotonic(), 1e-3), command)
            tail = self.read_line(max(deadline - time.monotonic(), 1e-3), command)
            if tail:
                self._out_of_step = True
                raise ProtocolError(
                    f"{self.name}: {len(tail)} unexpected characters after the block "
                    f"in reply to {command!r}"
                )
            self.transcript.append((time.monotonic(), "<", head + digits + b"..."))
            return payload

    # -- request/response -----------------------------------------------------------------
    def query(
        self,
        command: str,
        *,
        timeout: float | None = None,
        retries: int | None = None,
        parse: Callable[[str], T] | None = None,
        recover: Callable[[DriverError], None] | None = None,
    ) -> T | str:
        """Send ``command`` and return its reply line (parsed by ``parse`` if given).

        Parameters
        ----------
        command : str
            The query.
        timeout : float, optional
            Total time allowed for the reply [s] (default: the line's).
        retries : int, optional
            Extra attempts after a transient failure: :class:`ResponseTimeout` or
            :class:`ProtocolError` (default: the line's). Only for queries without side
            effects.
        parse : callable, optional
            Converts the reply text; raise :class:`ProtocolError` (or ``ValueError``,
            converted) for a reply that does not have the expected shape.
        recover : callable, optional
            Called with the failure before each retry and before the final failure is
            raised; it may raise a more specific error (e.g. the device's own).

        Raises
        ------
        ResponseTimeout, ProtocolError
            After the last attempt failed.
        TransportError
            At once if the port fails (not retried).
        """
        attempts = 1 + (self.retries if retries is None else int(retries))
        with self._lock:
            for attempt in range(attempts):
                try:
                    self.write(command)
                    self.exchanges += 1
                    reply = self.read_line(timeout, command)
                    if parse is None:
                        return reply
                    try:
                        return parse(reply)
                    except ValueError as exc:
                        raise ProtocolError(
                            f"{self.name}: unexpected reply {reply!r} to {command!r}: {exc}"
                        ) from exc
                except (ResponseTimeout, ProtocolError) as exc:
                    _log.debug("%s: attempt %d of %r failed: %s", self.name, attempt + 1, command, exc)
                    self._out_of_step = True
                    if recover is not None:
                        recover(exc)
                    if attempt + 1 == attempts:
                        raise
        raise AssertionError("unreachable")  # pragma: no cover

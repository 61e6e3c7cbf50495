"""Serial transports of the emulated instruments: pseudo-terminal, TCP loopback, in-process URL.

Every transport feeds received bytes into a :class:`LineSplitter` and hands complete lines
to the instrument's :class:`DeviceChannel`, which runs the firmware under a lock, applies
the injected faults and charges the line's transfer time to the simulated clock.

Robustness (docs/protocol.md, "Robustness"): no received byte sequence can stop a line.
:meth:`DeviceChannel.process` survives a firmware that raises, even from its error path,
and every serving loop (pseudo-terminal, TCP, and the in-process URL handler) answers
the next line whatever happened to the previous one, through :func:`reply_to`.
"""
from __future__ import annotations

import os
import re
import select
import socket
import termios
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import Callable, Iterator, Protocol

import numpy as np

from .clock import SimClock, transfer_time

__all__ = ["Firmware", "Faults", "LineSplitter", "DeviceChannel", "PtyTransport", "TcpTransport", "MAX_LINE",
           "reply_to", "garble_bytes"]

#: Longest accepted command line [bytes]; longer lines are discarded with an error.
MAX_LINE = 4096
_TERMINATOR = re.compile(rb"[\r\n]")


class Firmware(Protocol):
    """What a transport needs from an instrument's firmware."""

    def handle_line(self, line: str) -> bytes: ...

    def overlong_line(self) -> bytes: ...

    def internal_error(self, error: Exception) -> bytes: ...


@dataclass
class Faults:
    """Injected line faults of one instrument (side channel, see :class:`~drivers.emulator.rig.RigControl`).

    Attributes
    ----------
    disconnected : bool
        The instrument hears nothing and says nothing (cable pulled).
    stall_s : float
        Wall-clock seconds the instrument hangs before processing its next line (the reply
        then comes late; later lines queue up behind it).
    garble : int
        Number of next non-empty replies whose bytes are corrupted (terminator kept).
    """

    disconnected: bool = False
    stall_s: float = 0.0
    garble: int = 0
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(12345))


class LineSplitter:
    """Split a byte stream into lines at CR or LF (CR LF gives an empty line, ignored).

    A line is decoded as ASCII with Python's ``surrogateescape`` error handler: each byte
    >= 0x80 becomes the lone surrogate U+DC80 + (byte - 0x80).  Such a character is no
    letter, digit or blank for any parser, so it can only make a command invalid, and it
    maps back to exactly the byte received when an error text quotes it.

    Examples
    --------
    >>> s = LineSplitter()
    >>> list(s.feed(b"1TP\\r\\n2T")), list(s.feed(b"P\\r"))
    (['1TP'], ['2TP'])
    """

    OVERLONG = object()

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self.max_line = max_line
        self._buffer = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> Iterator["str | object"]:
        """Yield each completed line (str), or :attr:`OVERLONG` for a discarded long line."""
        start = 0
        for terminator in _TERMINATOR.finditer(data):
            self._extend(data[start:terminator.start()])
            yield from self._end_line()
            start = terminator.end()
        self._extend(data[start:])

    def _extend(self, chunk: bytes) -> None:
        """Add bytes of the current line; past ``max_line`` the line is discarded."""
        if self._discarding or not chunk:
            return
        self._buffer += chunk
        if len(self._buffer) > self.max_line:
            self._buffer.clear()
            self._discarding = True

    def _end_line(self) -> Iterator["str | object"]:
        """A terminator arrived: the line (if any), or OVERLONG if it was discarded."""
        if self._discarding:
            self._discarding = False
            yield self.OVERLONG
        elif self._buffer:
            yield self._buffer.decode("ascii", errors="surrogateescape")
        self._buffer.clear()


def _reply_bytes(reply: object) -> bytes:
    """A firmware's reply, which must be bytes (TypeError otherwise: a firmware bug)."""
    if not isinstance(reply, bytes):
        raise TypeError(f"firmware replied {type(reply).__name__}, expected bytes")
    return reply


#: Line time of one piece of a reply streamed in real-time mode [s] (:meth:`DeviceChannel.paced`).
STREAM_PIECE_S = 0.02


class DeviceChannel:
    """One instrument as seen from its serial line(s): firmware + lock + faults + timing.

    Parameters
    ----------
    name : str
        Instrument name (``stage``, ``camera``, ``lamp``).
    firmware : Firmware
        The command interpreter.
    clock : SimClock
        Shared simulated clock (charged with each line's transfer time).
    baudrate : int
        Line speed [bit/s].
    """

    def __init__(self, name: str, firmware: Firmware, clock: SimClock, baudrate: int) -> None:
        self.name = name
        self.firmware = firmware
        self.clock = clock
        self.baudrate = baudrate
        self.lock = threading.RLock()
        self.faults = Faults()
        self.lines_processed = 0
        self.last_internal_error: Exception | None = None
        #: Called with ``(device, simulated time, line, reply)`` after every line (a
        #: :class:`~drivers.emulator.control.TrafficLog`), or None.
        self.traffic: Callable[[str, float, object, bytes], None] | None = None

    def process(self, line: "str | object") -> bytes:
        """Run one received line through the firmware; return the reply bytes (maybe empty).

        Never raises because of the firmware: an exception from ``handle_line`` (or
        ``overlong_line``) is recorded in :attr:`last_internal_error` and handed to the
        firmware's ``internal_error``; if that raises too, the line gets no reply and the
        later exception is recorded (the first is its ``__context__``).
        """
        faults = self.faults
        if faults.disconnected:
            return b""
        if faults.stall_s > 0:
            stall, faults.stall_s = faults.stall_s, 0.0
            time.sleep(stall)
        with self.lock:
            reply = self._run_firmware(line)
            n_in = MAX_LINE if line is LineSplitter.OVERLONG else len(line) + 1  # type: ignore[arg-type]
            self.lines_processed += 1
            # real time: the reply's own transfer time passes as the transport streams it (:meth:`paced`)
            n_out = 0 if self.clock.realtime else len(reply)
            self.clock.advance(transfer_time(n_in + n_out, self.baudrate))
            if reply and faults.garble > 0:
                faults.garble -= 1
                reply = self._garbled(reply)
            if self.traffic is not None:
                self.traffic(self.name, self.clock.now(), line, reply)
        if faults.disconnected:
            return b""
        return reply

    def paced(self, reply: bytes) -> Iterator[bytes]:
        """The reply in the pieces a transport writes: whole in event and wall modes; in real-time mode
        in pieces of :data:`STREAM_PIECE_S` of line time, each released when the line would
        have carried it (at the clock's speed), so a long reply (``FRAME?``, 43 s at 115200 baud) arrives byte by
        byte as on a real line and a client's read timeout sees data flowing."""
        if not self.clock.realtime or len(reply) <= 1:
            yield reply
            return
        per_piece = max(1, int(STREAM_PIECE_S * self.baudrate / 10))
        start, speed = time.monotonic(), self.clock.speed
        for offset in range(0, len(reply), per_piece):
            piece = reply[offset:offset + per_piece]
            due = start + transfer_time(offset + len(piece), self.baudrate) / speed
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            yield piece

    def _run_firmware(self, line: "str | object") -> bytes:
        """The firmware's reply to one line, or its error path's reply, or ``b""``."""
        try:
            if line is LineSplitter.OVERLONG:
                return _reply_bytes(self.firmware.overlong_line())
            return _reply_bytes(self.firmware.handle_line(line))  # type: ignore[arg-type]
        except Exception as error:  # a firmware bug must not kill the line
            self.last_internal_error = error
            try:
                return _reply_bytes(self.firmware.internal_error(error))
            except Exception as error_path_error:  # ... nor a bug in its error path
                self.last_internal_error = error_path_error
                return b""

    def _garbled(self, reply: bytes) -> bytes:
        body = bytearray(reply.rstrip(b"\r\n"))
        tail = reply[len(body):]
        rng = self.faults.rng
        for i in range(len(body)):
            if rng.random() < 0.5:
                body[i] = int(rng.integers(33, 127))  # printable noise, never a terminator
        if not body:
            body = bytearray(b"?")
        return bytes(body) + tail


def reply_to(channel: DeviceChannel, line: "str | object") -> bytes:
    """``channel.process(line)`` for a serving loop: any exception becomes no reply.

    :meth:`DeviceChannel.process` already contains the firmware's failures; this guard
    keeps a serving thread alive against anything else (a fault injected with bad
    values, a clock refusing a time), and records the exception in the channel's
    ``last_internal_error``.
    """
    try:
        return channel.process(line)
    except Exception as error:
        channel.last_internal_error = error
        return b""


class _Worker:
    """Shared stop flag for transport threads."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _spawn(self, target: Callable[..., None], *args, name: str) -> None:
        thread = threading.Thread(target=target, args=args, name=name, daemon=True)
        self._threads.append(thread)
        thread.start()

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=2.0)


def _termios_speed(baudrate: int) -> int | None:
    """The termios speed constant of ``baudrate`` (``termios.B19200`` ...), None if there is none."""
    return getattr(termios, f"B{int(baudrate)}", None)


def garble_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    """What a UART at the wrong rate makes of ``data``: every byte but CR and LF becomes noise.

    The noise bytes are >= 0x80 (never a letter, digit, blank or terminator), so garbled
    input can only make commands invalid; line terminators are kept, so lines still end.

    Examples
    --------
    >>> out = garble_bytes(b"1TP\\r", np.random.default_rng(0))
    >>> len(out), out[-1:], all(b >= 0x80 for b in out[:-1])
    (4, b'\\r', True)
    """
    noise = rng.integers(0x80, 0x100, size=len(data), dtype=np.uint8)
    raw = np.frombuffer(data, dtype=np.uint8)
    keep = (raw == 0x0D) | (raw == 0x0A)
    return np.where(keep, raw, noise).astype(np.uint8).tobytes()


class PtyTransport(_Worker):
    """The instrument on a pseudo-terminal in raw mode (``/dev/pts/N``, optional symlink).

    The emulator keeps the terminal's slave side open, so a client may open and close the
    port path as often as it likes.  The terminal starts at the instrument's baud rate.

    Baud rate check (``check_baudrate``, default on): a real serial line whose two ends run
    at different rates carries garbage.  The master side of a pty sees the termios settings
    the client gave the slave side, so when the client's output rate differs from the
    instrument's, the instrument hears :func:`garble_bytes` of what was sent (every command
    is invalid, an error is queued) and any reply is garbled the same way: the client sees
    timeouts and noise, as it would in the lab.

    Parameters
    ----------
    channel : DeviceChannel
        The instrument.
    symlink : str, optional
        Path of a symlink to create to the terminal.
    check_baudrate : bool
        Garble the traffic while the client's rate differs from the instrument's.
    """

    def __init__(self, channel: DeviceChannel, symlink: str | None = None, check_baudrate: bool = True) -> None:
        super().__init__()
        self.channel = channel
        self.check_baudrate = bool(check_baudrate)
        self._speed = _termios_speed(channel.baudrate)
        self._noise = np.random.default_rng(channel.baudrate)
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self.master)
        if self._speed is not None:
            attributes = termios.tcgetattr(self._slave)
            attributes[4] = attributes[5] = self._speed
            termios.tcsetattr(self._slave, termios.TCSANOW, attributes)
        self.path = os.ttyname(self._slave)
        self.symlink = symlink
        if symlink:
            if os.path.islink(symlink):
                os.unlink(symlink)
            os.symlink(self.path, symlink)
        self._spawn(self._serve, name=f"gonio-pty-{channel.name}")

    @property
    def address(self) -> str:
        return self.symlink or self.path

    def _serve(self) -> None:
        splitter = LineSplitter()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self.master], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(self.master, 65536)
            except OSError:
                return
            wrong_rate = self.rate_mismatch()
            if wrong_rate:
                data = garble_bytes(data, self._noise)
            for line in splitter.feed(data):
                reply = reply_to(self.channel, line)
                for piece in self.channel.paced(reply) if reply else ():
                    self._write(garble_bytes(piece, self._noise) if wrong_rate else piece)

    def rate_mismatch(self) -> bool:
        """Whether the check is on and the client's output rate differs from the instrument's."""
        if not self.check_baudrate or self._speed is None:
            return False
        try:
            return termios.tcgetattr(self.master)[5] != self._speed
        except termios.error:
            return False

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view and not self._stop.is_set():
            try:
                _, ready, _ = select.select([], [self.master], [], 0.05)
                if ready:
                    n = os.write(self.master, view)
                    view = view[n:]
            except OSError:
                return

    def close(self) -> None:
        super().close()
        if self.symlink and os.path.islink(self.symlink):
            os.unlink(self.symlink)
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


def _quick_ack(conn: socket.socket) -> None:
    """Acknowledge every received segment at once (Linux ``TCP_QUICKACK``; elsewhere nothing).

    A client that writes a command without a reply and then a query (``EXP 0.01`` then
    ``SYST:ERR?``) has its second segment held back by Nagle's algorithm until the first is
    acknowledged; a receiver that delays its ACKs (40 ms on Linux) then stalls every such
    pair.  ``TCP_NODELAY`` on the client avoids the stall, but a plain pyserial
    ``socket://`` client does not set it: so the emulator does not delay its ACKs.  Linux
    clears the option after use, so it is set again before every ``recv``.
    """
    option = getattr(socket, "TCP_QUICKACK", None)
    if option is not None:
        try:
            conn.setsockopt(socket.IPPROTO_TCP, option, 1)
        except OSError:  # not supported for this socket: delayed ACKs remain
            pass


#: How long a new TCP client waits for the previous one to close before it is refused [s]
#: (a client that has just closed is seen within one 0.05 s poll of its connection).
HANDOVER_WAIT = 0.5


class TcpTransport(_Worker):
    """The instrument on a TCP socket bound to 127.0.0.1 (``socket://127.0.0.1:PORT``).

    Replies are sent at once (``TCP_NODELAY``) and received segments are acknowledged at
    once (:func:`_quick_ack`), so that a client that sets neither option (pyserial's
    ``socket://`` handler) sees no Nagle/delayed-ACK stall either.

    One client at a time, as a serial line has one controller and a terminal server in
    exclusive mode allows one connection per port: a connection made while another is
    open (after :data:`HANDOVER_WAIT` for the first to close, when it is just leaving) is
    closed at once, so that two programs never drive one instrument in turn, each acting
    on a state the other changed (two ``gonio run`` on one emulator recorded wrong rows).

    Parameters
    ----------
    channel : DeviceChannel
        The instrument.
    port : int
        TCP port; 0 picks a free one.
    host : str
        Interface to bind; the loopback interface unless explicitly asked otherwise.
    """

    def __init__(self, channel: DeviceChannel, port: int = 0, host: str = "127.0.0.1") -> None:
        super().__init__()
        self.channel = channel
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.bind((host, port))
        self._server.listen(4)
        self._server.settimeout(0.05)
        self.host, self.port = self._server.getsockname()[:2]
        self._free = threading.Event()
        self._free.set()
        self._spawn(self._accept, name=f"gonio-tcp-{channel.name}")

    @property
    def address(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            if not self._free.wait(HANDOVER_WAIT):
                conn.close()  # another client holds the instrument
                continue
            self._free.clear()
            self._spawn(self._serve, conn, name=f"gonio-tcp-{self.channel.name}-client")

    def _serve(self, conn: socket.socket) -> None:
        try:
            self._serve_client(conn)
        finally:
            self._free.set()

    def _serve_client(self, conn: socket.socket) -> None:
        splitter = LineSplitter()
        conn.settimeout(0.05)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with conn:
            while not self._stop.is_set():
                _quick_ack(conn)
                try:
                    data = conn.recv(65536)
                except socket.timeout:
                    continue
                except OSError:
                    return
                if not data:
                    return
                for line in splitter.feed(data):
                    reply = reply_to(self.channel, line)
                    try:
                        for piece in self.channel.paced(reply) if reply else ():
                            conn.sendall(piece)
                    except OSError:
                        return

    def close(self) -> None:
        self._stop.set()
        self._server.close()
        super().close()

"""In-process pyserial port ``gonio-sim://<device>?rig=<name>`` to an emulated instrument.

pyserial finds URL handlers as modules ``<package>.protocol_<scheme>`` of the packages in
``serial.protocol_handler_packages``; an :class:`~drivers.emulator.rig.EmulatedRig`
registers ``drivers.emulator`` there when it starts, and the modules
``protocol_gonio-sim`` / ``protocol_goniosim`` of this package re-export :class:`Serial`.
No OS port is involved: bytes go straight to the instrument's firmware thread.

A port opened with a baud rate other than the instrument's (19200 stage, 115200 camera,
9600 lamp) behaves like a mis-configured real line: the instrument hears only noise, so
nothing is answered.
"""
from __future__ import annotations

import queue
import threading
import time
import urllib.parse

from serial import SerialBase, SerialException
from serial.serialutil import PortNotOpenError

from .transports import DeviceChannel, LineSplitter, reply_to

__all__ = ["Serial", "SCHEMES"]

SCHEMES = ("gonio-sim", "goniosim")


def _lookup_channel(url: str) -> DeviceChannel:
    from .rig import find_rig  # late import: rig imports transports, not this module

    parts = urllib.parse.urlsplit(url)
    if parts.scheme.lower() not in SCHEMES:
        raise SerialException(f"expected gonio-sim://<device>?rig=<name>, got {url!r}")
    options = urllib.parse.parse_qs(parts.query)
    unknown = set(options) - {"rig"}
    if unknown:
        raise SerialException(f"{url!r}: unknown option(s) {sorted(unknown)}; only 'rig' is allowed")
    rig_name = options.get("rig", ["default"])[0]
    rig = find_rig(rig_name)
    if rig is None:
        raise SerialException(f"{url!r}: no emulated rig named {rig_name!r} is running in this process")
    device = parts.netloc or parts.path.lstrip("/")
    if device not in rig.channels:
        raise SerialException(f"{url!r}: unknown device {device!r}; expected one of {sorted(rig.channels)}")
    return rig.channels[device]


class Serial(SerialBase):
    """pyserial ``Serial`` talking to an emulated instrument in the same process."""

    def __init__(self, *args, **kwargs) -> None:
        self._channel: DeviceChannel | None = None
        self._rx = bytearray()
        self._rx_ready = threading.Condition()
        self._inbox: "queue.Queue[bytes | None]" = queue.Queue()
        self._worker: threading.Thread | None = None
        super().__init__(*args, **kwargs)

    # -- lifecycle --------------------------------------------------------------------
    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self._channel = _lookup_channel(self._port)
        self._rx.clear()
        self._inbox = queue.Queue()
        self._worker = threading.Thread(target=self._serve, name=f"gonio-sim-{self._channel.name}", daemon=True)
        self.is_open = True
        self._worker.start()

    def close(self) -> None:
        if self.is_open:
            self.is_open = False
            self._inbox.put(None)
            if self._worker is not None and self._worker is not threading.current_thread():
                self._worker.join(timeout=2.0)
        super().close()

    def _reconfigure_port(self) -> None:
        """Line settings are stored; a baud rate mismatch makes the line deaf (see module doc)."""

    def from_url(self, url: str) -> str:
        return url

    def _serve(self) -> None:
        splitter = LineSplitter()
        while True:
            data = self._inbox.get()
            if data is None:
                return
            channel = self._channel
            if channel is None or self._baudrate != channel.baudrate:
                continue
            for line in splitter.feed(data):
                reply = reply_to(channel, line)  # never raises: the port stays served
                for piece in channel.paced(reply) if reply else ():
                    with self._rx_ready:
                        self._rx.extend(piece)
                        self._rx_ready.notify_all()

    # -- data -------------------------------------------------------------------------
    @property
    def in_waiting(self) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        with self._rx_ready:
            return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        if not self.is_open:
            raise PortNotOpenError()
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        with self._rx_ready:
            while len(self._rx) < size:
                if deadline is None:
                    self._rx_ready.wait(0.1)
                    if not self.is_open:
                        break
                    continue
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._rx_ready.wait(remaining)
            data = bytes(self._rx[:size])
            del self._rx[:size]
        return data

    def write(self, data) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        payload = bytes(data)
        self._inbox.put(payload)
        return len(payload)

    def reset_input_buffer(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        with self._rx_ready:
            self._rx.clear()

    def reset_output_buffer(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def out_waiting(self) -> int:
        return 0

    def cancel_read(self) -> None:
        with self._rx_ready:
            self._rx_ready.notify_all()

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True

"""The emulated rig from outside its process: a control channel and a traffic log.

:class:`ControlServer` serves the rig's side channel (:class:`~drivers.emulator.rig.RigControl`:
faults, the clock, the ground truth) on a loopback TCP port as JSON lines, so that a test
in another process (a lab framework's own test suite, a notebook driving the rig with
pyvisa) can inject a fault, let simulated time pass or read where the axes really are, as
lewis's control server and caproto's simulated IOCs allow. One request per line, one reply
per line::

    > {"op": "advance", "args": {"seconds": 5}}
    < {"ok": true, "result": null}
    > {"op": "true_state"}
    < {"ok": true, "result": {"time_s": 5.0, "positions_deg": [0.0, 0.0, 0.0], ...}}
    > {"op": "stall", "args": {"device": "printer", "seconds": 1}}
    < {"ok": false, "error": "device must be one of ['camera', 'lamp', 'stage'], got 'printer'"}

The operations are :data:`OPERATIONS` (docs/emulator.md, "Control from outside"). A
request is carried out under the locks of every instrument's line, so it never lands in
the middle of a command a client sent.

:class:`TrafficLog` writes every line each instrument received and its reply, with the
simulated and the wall time, as JSON lines (``gonio emulator --log-traffic FILE``).
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import socketserver
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

__all__ = ["ControlServer", "TrafficLog", "OPERATIONS", "handle_request"]

#: Operations of the control channel: the name, and the arguments it takes (all by name).
OPERATIONS: Mapping[str, tuple[str, ...]] = {
    "now": (),
    "advance": ("seconds",),
    "pause": (),
    "resume": (),
    "set_speed": ("speed",),
    "clock": (),
    "true_state": (),
    "disconnect": ("device",),
    "reconnect": ("device",),
    "stall": ("device", "seconds"),
    "garble": ("device", "replies"),
    "burn_out_lamp": (),
    "replace_lamp": (),
    "hit_limit": ("axis",),
    "camera_fault": ("active",),
    "clear_faults": (),
    "power_cycle_stage": (),
    "remount": ("mounting", "rotation_deg", "spin", "handling_s"),
}
#: Operations that let time pass or wait: carried out without the lines' locks (a client
#: may be waiting on the rig meanwhile).
_UNLOCKED = frozenset({"now", "advance", "pause", "resume", "set_speed", "clock"})
#: Longest request line [bytes].
MAX_REQUEST = 4096


def _jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        return {k: _jsonable(v) for k, v in dataclasses.asdict(value).items()}
    if isinstance(value, (tuple, list)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item"):  # a numpy scalar
        return value.item()
    return value


def handle_request(control, locks: list, line: bytes) -> dict[str, Any]:
    """The reply to one request line (module notes): ``{"ok": true, "result": ...}`` or
    ``{"ok": false, "error": "..."}`` naming what was wrong and what was expected."""
    try:
        request = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        return {"ok": False, "error": f"not a JSON object ({error}); expected e.g. "
                                      '{"op": "advance", "args": {"seconds": 5}}'}
    if not isinstance(request, dict) or request.get("op") not in OPERATIONS:
        op = request.get("op") if isinstance(request, dict) else None
        return {"ok": False, "error": f"op {op!r}: expected one of {sorted(OPERATIONS)}"}
    op, args = request["op"], request.get("args", {})
    unknown = sorted(set(args) - set(OPERATIONS[op])) if isinstance(args, dict) else ["(not an object)"]
    if unknown:
        return {"ok": False, "error": f"{op}: unknown argument(s) {unknown}; it takes {list(OPERATIONS[op])}"}
    with contextlib.ExitStack() as stack:
        if op not in _UNLOCKED:
            for lock in locks:
                stack.enter_context(lock)
        try:
            result = getattr(control, op)(**args)
        except (TypeError, ValueError) as error:
            return {"ok": False, "error": f"{op}: {error}"}
    return {"ok": True, "result": _jsonable(result)}


class _Handler(socketserver.StreamRequestHandler):
    def handle(self) -> None:
        server: "_Server" = self.server  # type: ignore[assignment]
        while True:
            line = self.rfile.readline(MAX_REQUEST + 1)
            if not line:
                return
            if len(line) > MAX_REQUEST:
                reply = {"ok": False, "error": f"request longer than {MAX_REQUEST} bytes"}
            else:
                reply = handle_request(server.control, server.locks, line.strip())
            self.wfile.write((json.dumps(reply) + "\n").encode("utf-8"))
            self.wfile.flush()


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address, control, locks) -> None:
        self.control, self.locks = control, locks
        super().__init__(address, _Handler)


class ControlServer:
    """The control channel of an emulated rig on ``127.0.0.1:port`` (module notes).

    Parameters
    ----------
    rig : drivers.emulator.rig.EmulatedRig
    port : int
        TCP port (0: a free one; :attr:`port` says which).
    """

    def __init__(self, rig, port: int = 0) -> None:
        locks = [channel.lock for _, channel in sorted(rig.channels.items())]
        self._server = _Server(("127.0.0.1", int(port)), rig.control, locks)
        self.port: int = self._server.server_address[1]
        self._thread = threading.Thread(target=self._server.serve_forever, name="gonio-control", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop serving and close the port."""
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)


def _printable(data: bytes) -> str:
    """Bytes as printable ASCII, others (terminators included) as ``\\xNN``."""
    return "".join(chr(b) if 0x20 <= b < 0x7F and b != 0x5C else f"\\x{b:02x}" for b in data)


class TrafficLog:
    """Every line the instruments receive and their replies, as JSON lines in ``path``:
    ``{"device", "sim_time" [s], "wall_time" (ISO 8601), "received", "replied"}`` (bytes
    that are not printable ASCII, the replies' terminators included, escaped as ``\\xNN``; a
    block reply such as ``FRAME?``'s abbreviated to its header and length). Appended and
    flushed line by line."""

    #: Longest reply logged whole [bytes]; longer ones are abbreviated.
    MAX_LOGGED = 512

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._file = self.path.open("a", encoding="ascii", buffering=1)
        self._lock = threading.Lock()

    def record(self, device: str, sim_time: float, received: "str | object", replied: bytes) -> None:
        """Log one exchange."""
        text = received if isinstance(received, str) else "<line longer than the input buffer>"
        entry = {"device": device, "sim_time": round(sim_time, 6),
                 "wall_time": datetime.now(timezone.utc).isoformat(timespec="milliseconds"),
                 "received": _printable(text.encode("utf-8", "surrogateescape")),
                 "replied": self._reply_text(replied)}
        with self._lock:
            self._file.write(json.dumps(entry) + "\n")

    def _reply_text(self, reply: bytes) -> str:
        """The reply as printable text: a definite-length block as its header and size
        (``#6491520<491520 bytes>``), anything else longer than :data:`MAX_LOGGED` cut."""
        if reply[:1] == b"#" and reply[1:2].isdigit():
            header = reply[:2 + int(reply[1:2])]
            return f"{_printable(header)}<{len(reply) - len(header) - 1} bytes>{_printable(reply[-1:])}"
        if len(reply) > self.MAX_LOGGED:
            return f"{_printable(reply[:self.MAX_LOGGED])}... ({len(reply)} bytes)"
        return _printable(reply)

    def close(self) -> None:
        with self._lock:
            self._file.close()

    __call__ = record

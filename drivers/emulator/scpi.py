"""Shared SCPI (IEEE 488.2) machinery of the emulated camera and lamp supply.

Implements what docs/protocol.md specifies for both SCPI instruments: keyword matching in
long and short form, ``;``-separated message units, common commands (``*IDN?``,
``*RST``, ``*CLS``, ``*OPC?``), ``SYSTem:ERRor?`` with a bounded error queue, numeric
parameters with ``MIN``/``MAX``/``DEF``, and the IEEE 488.2 rule that a failing query
produces no reply (its error is queued).

References
----------
IEEE Std 488.2-1992, sections 6.1 (message exchange), 7.7 (program data, definite-length
block) and 11.5 (``*OPC``); SCPI Consortium, "Standard Commands for Programmable
Instruments" 1999.0, vol. 1 section 6 (keywords, short form) and vol. 2 ``SYSTem:ERRor``
(error queue, -350 queue overflow) and section 21.8 (error numbers).
"""
from __future__ import annotations

import re
from collections import deque
from typing import Callable, Sequence

__all__ = ["ScpiError", "ErrorQueue", "ScpiInstrument", "keyword_matches", "parse_number", "format_number",
           "definite_length_block", "expect_args"]

#: Standard SCPI error messages used by the emulated instruments.
MESSAGES = {
    0: "No error",
    -100: "Command error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -200: "Execution error",
    -221: "Settings conflict",
    -222: "Data out of range",
    -350: "Queue overflow",
}


class ScpiError(Exception):
    """An error to queue: standard code and an optional device-specific detail."""

    def __init__(self, code: int, detail: str = "") -> None:
        self.code = code
        self.detail = detail
        super().__init__(self.text())

    def text(self) -> str:
        """The ``SYST:ERR?`` reply for this error: ``<code>,"<message>[;<detail>]"``."""
        message = MESSAGES.get(self.code, "Error")
        if self.detail:
            message = f"{message};{self.detail}"
        return f'{self.code},"{message}"'


class ErrorQueue:
    """The SCPI error/event queue: oldest first, bounded, ``-350`` on overflow.

    Examples
    --------
    >>> q = ErrorQueue(size=2)
    >>> for code in (-113, -222, -104): q.push(ScpiError(code))
    >>> q.pop(), q.pop(), q.pop()
    ('-113,"Undefined header"', '-350,"Queue overflow"', '0,"No error"')
    """

    def __init__(self, size: int = 16) -> None:
        self.size = size
        self._queue: deque[str] = deque()

    def push(self, error: ScpiError) -> None:
        """Queue an error; when full, the newest entry becomes ``-350`` (SCPI vol. 2)."""
        if len(self._queue) >= self.size:
            self._queue[-1] = ScpiError(-350).text()
            return
        self._queue.append(error.text())

    def pop(self) -> str:
        """Remove and return the oldest error, ``0,"No error"`` if empty."""
        return self._queue.popleft() if self._queue else ScpiError(0).text()

    def clear(self) -> None:
        """Empty the queue (``*CLS``)."""
        self._queue.clear()

    def __len__(self) -> int:
        return len(self._queue)


def keyword_matches(token: str, keyword: str) -> bool:
    """Whether ``token`` is the short or the long form of a SCPI keyword.

    The short form is the upper-case part of ``keyword`` (``EXPosure`` -> ``EXP``).

    Examples
    --------
    >>> keyword_matches("exp", "EXPosure"), keyword_matches("EXPOSURE", "EXPosure"), keyword_matches("EXPO", "EXPosure")
    (True, True, False)
    """
    token = token.upper()
    short = "".join(ch for ch in keyword if not ch.islower())
    return token == short or token == keyword.upper()


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def parse_number(text: str, name: str, low: float, high: float, default: float) -> float:
    """Parse a SCPI numeric parameter (decimal or ``MIN``/``MAX``/``DEF``) within [low, high].

    Raises
    ------
    ScpiError
        -104 when not a number, -222 when outside the range.
    """
    word = text.strip().upper()
    if word in ("MIN", "MINIMUM"):
        return low
    if word in ("MAX", "MAXIMUM"):
        return high
    if word in ("DEF", "DEFAULT"):
        return default
    if not _NUMBER.match(word):
        raise ScpiError(-104, f"{name} expects a number, got {text.strip()!r}")
    value = float(word)
    if not low <= value <= high:
        raise ScpiError(-222, f"{name} must be within {low:g}..{high:g}, got {value:g}")
    return value


def format_number(value: float) -> str:
    """Shortest SCPI numeric reply: integers without decimals, else ``%.6g``.

    Examples
    --------
    >>> format_number(120.0), format_number(0.025), format_number(1e-5)
    ('120', '0.025', '1e-05')
    """
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.6g}"


def definite_length_block(payload: bytes) -> bytes:
    """IEEE 488.2 definite-length arbitrary block ``#<d><len><bytes>``.

    Examples
    --------
    >>> definite_length_block(b"abc")
    b'#13abc'
    """
    length = str(len(payload)).encode()
    return b"#" + str(len(length)).encode() + length + payload


Handler = Callable[[list[str]], "str | bytes | None"]


class ScpiInstrument:
    """Base class of a SCPI instrument firmware: parse lines, dispatch, queue errors.

    Subclasses register commands with :meth:`add` and implement :meth:`reset` and
    :meth:`identity`.  :meth:`handle_line` returns the complete reply (with its LF
    terminator) or ``b""`` when the line holds no successful query.
    """

    reply_terminator = b"\n"

    def __init__(self) -> None:
        self.errors = ErrorQueue()
        self._commands: list[tuple[tuple[str, ...], bool, Handler]] = []
        self.add("*IDN", True, lambda args: self.identity())
        self.add("*RST", False, lambda args: self.reset())
        self.add("*CLS", False, lambda args: self.errors.clear())
        self.add("*OPC", True, lambda args: "1")
        self.add("*WAI", False, lambda args: None)
        self.add("SYSTem:ERRor", True, lambda args: self.errors.pop())
        self.add("SYSTem:ERRor:NEXT", True, lambda args: self.errors.pop())

    # -- to override -------------------------------------------------------------------
    def identity(self) -> str:  # pragma: no cover - overridden
        raise NotImplementedError

    def reset(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    # -- registration and dispatch ----------------------------------------------------
    def add(self, header: str, query: bool, handler: Handler) -> None:
        """Register ``header`` (keywords joined by ``:``, long form with short part in capitals)."""
        self._commands.append((tuple(header.split(":")), query, handler))

    def _find(self, header: str, query: bool) -> Handler:
        tokens = header.lstrip(":").split(":")
        for keywords, is_query, handler in self._commands:
            if is_query != query or len(keywords) != len(tokens):
                continue
            if all(
                (t.upper() == k.upper()) if k.startswith("*") else keyword_matches(t, k)
                for t, k in zip(tokens, keywords)
            ):
                return handler
        raise ScpiError(-113, f"{header}{'?' if query else ''}")

    def execute_unit(self, unit: str) -> str | bytes | None:
        """Execute one message unit (``HEADER[?] [param,...]``); return its reply or None."""
        unit = unit.strip()
        match = re.match(r"^(:?[*A-Za-z][A-Za-z0-9:]*)(\?)?(?:\s+(.*))?$", unit)
        if not match:
            raise ScpiError(-100, repr(unit[:40]))
        header, question, rest = match.group(1), bool(match.group(2)), match.group(3)
        args = [a.strip() for a in rest.split(",")] if rest is not None and rest.strip() else []
        handler = self._find(header, question)
        return handler(args)

    def handle_line(self, line: str) -> bytes:
        """Process one received line; return the reply bytes (possibly empty)."""
        replies: list[bytes] = []
        for unit in line.split(";"):
            if not unit.strip():
                continue
            try:
                reply = self.execute_unit(unit)
            except ScpiError as error:
                self.errors.push(error)
                continue
            except (ValueError, ArithmeticError) as error:  # e.g. a sample BRDF giving NaN
                self.internal_error(error)
                continue
            if reply is not None:
                replies.append(reply if isinstance(reply, bytes) else reply.encode("ascii"))
        if not replies:
            return b""
        return b";".join(replies) + self.reply_terminator

    def internal_error(self, error: Exception) -> bytes:
        """An unexpected failure while executing a line: queue -200 with its text, reply nothing."""
        self.errors.push(ScpiError(-200, str(error)[:80]))
        return b""

    def overlong_line(self) -> bytes:
        """Called for a line longer than the input buffer: queue -113, reply nothing."""
        self.errors.push(ScpiError(-113, "line too long"))
        return b""


def expect_args(args: Sequence[str], count: int) -> None:
    """Raise -109 (missing) or -108 (too many) unless exactly ``count`` parameters."""
    if len(args) < count:
        raise ScpiError(-109, f"expected {count} parameter(s), got {len(args)}")
    if len(args) > count:
        raise ScpiError(-108, f"expected {count} parameter(s), got {len(args)}")

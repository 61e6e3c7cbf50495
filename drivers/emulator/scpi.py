"""Shared SCPI (IEEE 488.2) machinery of the emulated camera and lamp supply.

Implements what docs/protocol.md specifies for both SCPI instruments: keyword matching in
long and short form, ``;``-separated message units, common commands (``*IDN?``,
``*RST``, ``*CLS``, ``*OPC?``, ``*WAI``; none takes a parameter), ``SYSTem:ERRor?`` with
a bounded error queue, numeric parameters with ``MIN``/``MAX``/``DEF``, strict integer
parameters, and the IEEE 488.2 rule that a failing query produces no reply (its error is
queued).

Every reply is printable ASCII (apart from the bytes of a definite-length block): an
error text that quotes received input escapes each non-printable or non-ASCII character
(``\\xNN`` for a received byte, see :func:`escape_nonprintable`) before it is queued, so
reading the error queue can never fail on what was received.

References
----------
IEEE Std 488.2-1992, sections 6.1 (message exchange), 7.7 (program data; 7.7.2 decimal
numeric program data), 8.7.8 (string response data: an embedded double quote is doubled),
8.7.9 (definite-length block response data), 10 (common commands, which take no
parameters here) and 11.5 (``*OPC``); SCPI Consortium, "Standard Commands for Programmable Instruments"
1999.0, vol. 1 section 6 (keywords, short form) and vol. 2 ``SYSTem:ERRor`` (error
queue, -350 queue overflow, description at most 255 characters) and section 21.8 (error
numbers: -108 parameter not allowed, -104 data type error).
"""
from __future__ import annotations

import re
from collections import deque
from typing import Callable, Sequence

__all__ = ["ScpiError", "ErrorQueue", "ScpiInstrument", "keyword_matches", "parse_number", "parse_integer",
           "format_number", "definite_length_block", "expect_args", "escape_nonprintable", "string_response",
           "MAX_ERROR_DESCRIPTION"]

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

#: Longest error description (message and device-dependent detail) [characters],
#: SCPI-1999 vol. 2 ``SYSTem:ERRor``.
MAX_ERROR_DESCRIPTION = 255


def _escape_char(char: str) -> str:
    """One character as printable ASCII (see :func:`escape_nonprintable`)."""
    code = ord(char)
    if 0x20 <= code < 0x7F:
        return "\\\\" if char == "\\" else char
    if 0xDC80 <= code <= 0xDCFF:  # a received byte >= 0x80, decoded with "surrogateescape"
        return f"\\x{code - 0xDC00:02x}"
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def escape_nonprintable(text: str) -> str:
    """``text`` as printable ASCII: other characters become backslash escapes.

    A received byte outside printable ASCII (a control character, or a byte >= 0x80,
    which the transports decode with Python's ``surrogateescape`` handler) becomes
    ``\\xNN``; a backslash becomes ``\\\\`` so that escapes stay unambiguous; any other
    non-ASCII character becomes ``\\uNNNN``.

    Examples
    --------
    >>> escape_nonprintable("EXP\\t1\\udce9")
    'EXP\\\\x091\\\\xe9'
    >>> escape_nonprintable("ROI?") == "ROI?"
    True
    """
    if text.isascii() and text.isprintable() and "\\" not in text:
        return text
    return "".join(_escape_char(char) for char in text)


def string_response(text: str, max_chars: int = MAX_ERROR_DESCRIPTION) -> str:
    """IEEE 488.2 string response data (8.7.8): ``text`` escaped, quoted, at most ``max_chars`` inside.

    Double quotes inside are doubled, the text is escaped with :func:`escape_nonprintable`
    and, if longer than ``max_chars``, cut at a character boundary and ended with ``...``.

    Examples
    --------
    >>> string_response('Command error;\\'"x\\'')
    '"Command error;\\'""x\\'"'
    >>> len(string_response("x" * 1000))
    257
    """
    if len(text) <= max_chars and text.isascii() and text.isprintable() and not ('"' in text or "\\" in text):
        return f'"{text}"'  # the common case, nothing to escape
    pieces = ['""' if char == '"' else _escape_char(char) for char in text]
    if sum(len(piece) for piece in pieces) > max_chars:
        kept, length = [], 0
        for piece in pieces:
            if length + len(piece) > max_chars - 3:
                break
            kept.append(piece)
            length += len(piece)
        pieces = kept + ["..."]
    return '"' + "".join(pieces) + '"'


class ScpiError(Exception):
    """An error to queue: standard code and an optional device-specific detail."""

    def __init__(self, code: int, detail: str = "") -> None:
        self.code = code
        self.detail = detail
        message = MESSAGES.get(code, "Error")
        if detail:
            message = f"{message};{detail}"
        self._text = f"{code},{string_response(message)}"
        super().__init__(self._text)

    def text(self) -> str:
        """The ``SYST:ERR?`` reply for this error: ``<code>,"<message>[;<detail>]"``.

        Always printable ASCII: the detail may quote received input, which
        :func:`string_response` escapes and bounds to :data:`MAX_ERROR_DESCRIPTION`.
        """
        return self._text


_NO_ERROR = ScpiError(0).text()


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
        return self._queue.popleft() if self._queue else _NO_ERROR

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


def _accepted_tokens(keyword: str) -> frozenset[str]:
    """Upper-case tokens that match ``keyword``: a common command exactly, else short and long form."""
    if keyword.startswith("*"):
        return frozenset({keyword.upper()})
    return frozenset({"".join(ch for ch in keyword if not ch.islower()), keyword.upper()})


# ASCII classes only: a Unicode digit or space is not part of a number or a separator.
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$", re.ASCII)
_INTEGER = re.compile(r"^[+-]?[0-9]+$", re.ASCII)
_UNIT = re.compile(r"^(:?[*A-Za-z][A-Za-z0-9:]*)(\?)?(?:\s+(.*))?$", re.ASCII)
#: More significant digits than any integer parameter of the instruments can need.
_MAX_INTEGER_DIGITS = 18


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
        raise ScpiError(-104, f"{name} expects a number, got '{text.strip()}'")
    value = float(word)
    if not low <= value <= high:
        raise ScpiError(-222, f"{name} must be within {low:g}..{high:g}, got {value:g}")
    return value


def parse_integer(text: str, name: str) -> int:
    """Parse an integer parameter strictly: optional sign and decimal digits, nothing else.

    This is the integer form of IEEE 488.2 decimal numeric program data (7.7.2); a
    fraction, an exponent, a doubled sign (``++1``) or any other character is a data type
    error. The caller checks the range.

    Raises
    ------
    ScpiError
        -104 when not an integer, -222 when it has more than 18 significant digits (far
        outside every range of the instruments).

    Examples
    --------
    >>> parse_integer("+0042", "x0"), parse_integer("-3", "x0")
    (42, -3)
    >>> parse_integer("++1", "x0")
    Traceback (most recent call last):
    ...
    drivers.emulator.scpi.ScpiError: -104,"Data type error;x0 expects an integer, got '++1'"
    """
    text = text.strip()
    if not _INTEGER.match(text):
        raise ScpiError(-104, f"{name} expects an integer, got '{text}'")
    if len(text.lstrip("+-").lstrip("0")) > _MAX_INTEGER_DIGITS:
        raise ScpiError(-222, f"{name} is out of range, got '{text}'")
    return int(text)


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


def _without_parameters(action: Callable[[], "str | None"]) -> Handler:
    """Handler of a command that takes no parameter: any parameter is -108 (IEEE 488.2, 10)."""
    def handler(args: list[str]) -> "str | None":
        expect_args(args, 0)
        return action()
    return handler


def _reply_bytes(reply: "str | bytes") -> bytes:
    """A handler's reply as bytes: a text reply is always printable ASCII."""
    if isinstance(reply, bytes):  # definite-length block: binary by design
        return reply
    if not (reply.isascii() and reply.isprintable()):
        reply = escape_nonprintable(reply)
    return reply.encode("ascii")


class ScpiInstrument:
    """Base class of a SCPI instrument firmware: parse lines, dispatch, queue errors.

    Subclasses register commands with :meth:`add` and implement :meth:`reset` and
    :meth:`identity`.  :meth:`handle_line` returns the complete reply (with its LF
    terminator) or ``b""`` when the line holds no successful query.
    """

    reply_terminator = b"\n"

    def __init__(self) -> None:
        self.errors = ErrorQueue()
        self._commands: list[tuple[tuple[frozenset[str], ...], bool, Handler]] = []
        self.add("*IDN", True, _without_parameters(lambda: self.identity()))
        self.add("*RST", False, _without_parameters(lambda: self.reset()))
        self.add("*CLS", False, _without_parameters(self.errors.clear))
        self.add("*OPC", True, _without_parameters(lambda: "1"))
        self.add("*WAI", False, _without_parameters(lambda: None))
        self.add("SYSTem:ERRor", True, _without_parameters(self.errors.pop))
        self.add("SYSTem:ERRor:NEXT", True, _without_parameters(self.errors.pop))

    # -- to override -------------------------------------------------------------------
    def identity(self) -> str:  # pragma: no cover - overridden
        raise NotImplementedError

    def reset(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    # -- parameter parsing for subclasses -------------------------------------------------
    @staticmethod
    def parse_integer(text: str, name: str) -> int:
        """Strict integer parameter (see :func:`parse_integer`)."""
        return parse_integer(text, name)

    # -- registration and dispatch ----------------------------------------------------
    def add(self, header: str, query: bool, handler: Handler) -> None:
        """Register ``header`` (keywords joined by ``:``, long form with short part in capitals)."""
        self._commands.append((tuple(_accepted_tokens(k) for k in header.split(":")), query, handler))

    def _find(self, header: str, query: bool) -> Handler:
        tokens = header.lstrip(":").upper().split(":")
        for keywords, is_query, handler in self._commands:
            if is_query != query or len(keywords) != len(tokens):
                continue
            if all(token in accepted for token, accepted in zip(tokens, keywords)):
                return handler
        raise ScpiError(-113, f"{header}{'?' if query else ''}")

    def execute_unit(self, unit: str) -> str | bytes | None:
        """Execute one message unit (``HEADER[?] [param,...]``); return its reply or None."""
        unit = unit.strip()
        match = _UNIT.match(unit)
        if not match:  # e.g. a header with a byte outside printable ASCII
            raise ScpiError(-100, f"'{unit[:40]}'")
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
                replies.append(_reply_bytes(reply))
        if not replies:
            return b""
        return b";".join(replies) + self.reply_terminator

    def internal_error(self, error: Exception) -> bytes:
        """An unexpected failure while executing a line: queue -200 with its text, reply nothing."""
        self.errors.push(ScpiError(-200, str(error)))
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

"""Shared SCPI (IEEE 488.2) machinery of the emulated camera and lamp supply.

Implements what docs/protocol.md specifies for both SCPI instruments: keyword matching in
long and short form, ``;``-separated message units, the IEEE 488.2 mandatory common
commands (``*IDN?``, ``*RST``, ``*CLS``, ``*ESE``, ``*ESE?``, ``*ESR?``, ``*OPC``,
``*OPC?``, ``*SRE``, ``*SRE?``, ``*STB?``, ``*TST?``, ``*WAI``) with the status model of
:mod:`drivers.emulator.status`, the SCPI-1999 required ``SYSTem:ERRor[:NEXT]?``,
``SYSTem:VERSion?`` and ``STATus`` subsystem (``OPERation``, ``QUEStionable``,
``PRESet``), a bounded error queue, numeric parameters with ``MIN``/``MAX``/``DEF``,
strict integer parameters, and the IEEE 488.2 rule that a failing query produces no
reply (its error is queued).

Overlapped commands (IEEE 488.2 12): a subclass reports the simulated time at which its
pending operations complete (:meth:`ScpiInstrument.pending_until`, e.g. the camera's
exposure).  A command registered with ``waits=True`` (every device command, ``*WAI``,
``*OPC?``, ``*TST?``) first lets that time pass; the status commands do not wait, so the
status can be polled while an operation runs, and ``*OPC`` sets the OPC event bit when it
completes.

Every reply is printable ASCII (apart from the bytes of a definite-length block): an
error text that quotes received input escapes each non-printable or non-ASCII character
(``\\xNN`` for a received byte, see :func:`escape_nonprintable`) before it is queued, so
reading the error queue can never fail on what was received.

References
----------
IEEE Std 488.2-1992, sections 6.1 (message exchange), 7.7 (program data; 7.7.2 decimal
numeric program data), 8.7.8 (string response data: an embedded double quote is doubled),
8.7.9 (definite-length block response data), 8.7.11 and 10.14 (``*IDN?`` replies
arbitrary ASCII response data, which ends the response message: a later query of the same
message is error -440), 10 (common commands), 11 (status reporting) and 12
(synchronisation, ``*OPC``, ``*WAI``); SCPI Consortium, "Standard Commands for Programmable Instruments"
1999.0, vol. 1 section 6 (keywords, short form) and vol. 2 ``SYSTem:ERRor`` (error
queue, -350 queue overflow, description at most 255 characters; ``SYSTem:VERSion?``),
section 20 (``STATus`` subsystem) and section 21.8 (error numbers: -108 parameter not
allowed, -104 data type error, -440 query unterminated after indefinite response).
"""
from __future__ import annotations

import re
from collections import deque
from typing import Callable, NamedTuple, Sequence

from .status import StatusModel

__all__ = ["ScpiError", "ErrorQueue", "ScpiInstrument", "keyword_matches", "parse_number", "parse_integer",
           "format_number", "definite_length_block", "expect_args", "escape_nonprintable", "string_response",
           "MAX_ERROR_DESCRIPTION", "SCPI_VERSION"]

#: Standard SCPI error messages used by the emulated instruments.
MESSAGES = {
    0: "No error",
    -100: "Command error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -131: "Invalid suffix",
    -138: "Suffix not allowed",
    -200: "Execution error",
    -221: "Settings conflict",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -350: "Queue overflow",
    -440: "Query UNTERMINATED after indefinite response",
}

#: ``SYSTem:VERSion?`` reply: the SCPI version the instruments comply with.
SCPI_VERSION = "1999.0"
#: Largest value of an IEEE 488.2 8-bit status mask (``*ESE``, ``*SRE``).
MASK_8_BIT = 255
#: Largest value of a SCPI 16-bit status register parameter (bit 15 is always 0).
MASK_SCPI_REGISTER = 32767

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

    def __init__(self, size: int = 16, on_error: Callable[[int], None] | None = None) -> None:
        self.size = size
        self.on_error = on_error
        self._queue: deque[str] = deque()

    def push(self, error: ScpiError) -> None:
        """Queue an error; when full, the newest entry becomes ``-350`` (SCPI vol. 2).

        ``on_error(code)`` (the status model: the SESR bit of the error's class) is called
        for every error, queued or not.
        """
        if self.on_error is not None:
            self.on_error(error.code)
        if len(self._queue) >= self.size:
            if self.on_error is not None:
                self.on_error(-350)  # a device-specific error (-300 class): DDE
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
#: A decimal number followed by a suffix (IEEE 488.2 7.7.3), e.g. ``25 ms``, ``1.2KV``.
_NUMBER_WITH_SUFFIX = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z][A-Za-z/0-9]*)$",
                                 re.ASCII)
#: Suffix multipliers (IEEE 488.2 table 7-2): ``M`` is milli, ``MA`` mega (SCPI-1999 vol. 1,
#: 7.2.3: ``MHZ`` and ``MOHM`` are the exceptions, mega).
_MULTIPLIERS = {"EX": 1e18, "PE": 1e15, "T": 1e12, "G": 1e9, "MA": 1e6, "K": 1e3, "M": 1e-3, "U": 1e-6,
                "N": 1e-9, "P": 1e-12, "F": 1e-15, "A": 1e-18}
_INTEGER = re.compile(r"^[+-]?[0-9]+$", re.ASCII)
_UNIT = re.compile(r"^(:?[*A-Za-z][A-Za-z0-9:]*)(\?)?(?:\s+(.*))?$", re.ASCII)
#: More significant digits than any integer parameter of the instruments can need.
_MAX_INTEGER_DIGITS = 18


def _suffix_scale(suffix: str, unit: str | None, name: str) -> float:
    """The factor a suffix gives a number in ``unit`` (``"MS"`` with unit ``"S"``: 1e-3).

    Raises
    ------
    ScpiError
        -138 when the parameter takes no suffix (``unit`` None), -131 when the suffix is not
        ``unit`` with an optional multiplier.
    """
    if unit is None:
        raise ScpiError(-138, f"{name} takes no suffix, got '{suffix}'")
    word, unit = suffix.upper(), unit.upper()
    if word == unit:
        return 1.0
    if word in ("MHZ", "MOHM") and word[1:] == unit:  # SCPI-1999 vol. 1, 7.2.3: mega, not milli
        return 1e6
    prefix = word[:-len(unit)] if word.endswith(unit) else None
    if prefix not in _MULTIPLIERS:
        raise ScpiError(-131, f"{name} expects a number in {unit} (with a multiplier such as M or U), got '{suffix}'")
    return _MULTIPLIERS[prefix]


def parse_number(text: str, name: str, low: float, high: float, default: float, unit: str | None = None) -> float:
    """Parse a SCPI numeric parameter (decimal, with a suffix, or ``MIN``/``MAX``/``DEF``) within [low, high].

    ``unit`` is the suffix the parameter takes (``"S"``, ``"V"``; IEEE 488.2 7.7.3, SCPI-1999
    vol. 1, 7.2.3), with a multiplier (``25 ms`` is 0.025 s, ``1.2 KV`` 1200 V); None: no suffix.

    Examples
    --------
    >>> parse_number("25 ms", "EXP", 0, 60, 0.01, unit="S"), parse_number("max", "EXP", 0, 60, 0.01)
    (0.025, 60)

    Raises
    ------
    ScpiError
        -104 when not a number, -131 or -138 for a wrong or unexpected suffix, -222 when
        outside the range.
    """
    word = text.strip().upper()
    if word in ("MIN", "MINIMUM"):
        return low
    if word in ("MAX", "MAXIMUM"):
        return high
    if word in ("DEF", "DEFAULT"):
        return default
    scale = 1.0
    with_suffix = _NUMBER_WITH_SUFFIX.match(word)
    if with_suffix and not _NUMBER.match(word):
        word, scale = with_suffix.group(1), _suffix_scale(with_suffix.group(2), unit, name)
    if not _NUMBER.match(word):
        raise ScpiError(-104, f"{name} expects a number, got '{text.strip()}'")
    value = float(word) * scale
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
    """A numeric reply in IEEE 488.2's response forms (8.7.2-8.7.4), six significant digits:
    an integer as NR1, a value from 1e-4 to 1e6 as NR2, others as NR3 (an explicit radix
    point, ``E``, a signed exponent).

    Examples
    --------
    >>> format_number(120.0), format_number(0.025), format_number(1e-5), format_number(2.5e20)
    ('120', '0.025', '1.0E-05', '2.5E+20')
    """
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    text = f"{value:.6g}"
    if "e" not in text:
        return text
    mantissa, exponent = text.split("e")
    return f"{mantissa if '.' in mantissa else mantissa + '.0'}E{exponent}"


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


class _Keyword(NamedTuple):
    """One node of a registered header: the tokens it accepts, and whether it may be left out."""

    tokens: frozenset[str]
    optional: bool


#: A node of a header pattern: ``[:KEYword]``, ``[KEYword:]`` (optional) or ``KEYword``.
_PATTERN_NODE = re.compile(r"\[:?([*A-Za-z][A-Za-z0-9]*):?\]|([*A-Za-z][A-Za-z0-9]*)", re.ASCII)


def header_keywords(pattern: str) -> tuple[_Keyword, ...]:
    """The nodes of a header pattern in SCPI-1999 notation (vol. 1, 6.2.5-6.2.6: long form
    with the short form in capitals, optional nodes in brackets).

    Examples
    --------
    >>> [(sorted(k.tokens), k.optional) for k in header_keywords("[SOURce:]VOLTage[:LEVel]")]
    [(['SOUR', 'SOURCE'], True), (['VOLT', 'VOLTAGE'], False), (['LEV', 'LEVEL'], True)]
    """
    nodes = []
    for match in _PATTERN_NODE.finditer(pattern):
        keyword, optional = (match.group(1), True) if match.group(1) else (match.group(2), False)
        nodes.append(_Keyword(_accepted_tokens(keyword), optional))
    if not nodes or all(node.optional for node in nodes):
        raise ValueError(f"header pattern {pattern!r}: expected at least one keyword that is not optional")
    return tuple(nodes)


def _matches(tokens: Sequence[str], keywords: Sequence[_Keyword]) -> bool:
    """Whether received ``tokens`` spell ``keywords``, optional ones left out or given."""
    if not keywords:
        return not tokens
    first, rest = keywords[0], keywords[1:]
    if first.optional and _matches(tokens, rest):
        return True
    return bool(tokens) and tokens[0] in first.tokens and _matches(tokens[1:], rest)


def _header_tokens(header: str, path: Sequence[str]) -> list[str]:
    """The nodes a received header names (upper case): a common command alone, from the
    root after a leading ``:``, else after the current ``path``."""
    if header.startswith("*"):
        return [header.upper()]
    if header.startswith(":"):
        return header[1:].upper().split(":")
    return [*path, *header.upper().split(":")]


def _path_after(unit: str, path: tuple[str, ...]) -> tuple[str, ...]:
    """The current path after the message unit ``unit``: its header's nodes less the last
    (SCPI-1999 vol. 1, 6.2.4); unchanged by a common command or a unit without a header.

    >>> _path_after("STAT:OPER:ENAB 16", ()), _path_after("*CLS", ("STAT",)), _path_after(":OUTP ON", ("X",))
    (('STAT', 'OPER'), ('STAT',), ())
    """
    match = _UNIT.match(unit.strip())
    if not match or match.group(1).startswith("*"):
        return path
    return tuple(_header_tokens(match.group(1), path)[:-1])


class _Command(NamedTuple):
    """A registered command: its header's nodes, query form, handler, whether it waits."""

    keywords: tuple[_Keyword, ...]
    query: bool
    handler: Handler
    waits: bool
    header: str


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
    """Base class of a SCPI instrument firmware: parse lines, dispatch, queue errors, report status.

    Subclasses register commands with :meth:`add`, set ``self.clock`` (a
    :class:`~drivers.emulator.clock.SimClock`) and implement :meth:`reset` and
    :meth:`identity`; they may override :meth:`pending_until`,
    :meth:`operation_condition`, :meth:`questionable_condition` and :meth:`self_test`.
    :meth:`handle_line` returns the complete reply (with its LF terminator) or ``b""`` when
    the line holds no successful query.
    """

    reply_terminator = b"\n"
    clock = None  # set by the subclass

    def __init__(self) -> None:
        self.status = StatusModel()
        self.errors = ErrorQueue(on_error=self.status.record_error)
        self._commands: list[_Command] = []
        self._replies_waiting = False
        self._indefinite_reply = False
        self.add("*IDN", True, _without_parameters(self._identify), waits=False)
        self.add("*RST", False, _without_parameters(self._reset_command), waits=False)
        self.add("*CLS", False, _without_parameters(self._clear_status), waits=False)
        self.add("*ESE", False, self._set_mask("ESE", "ese"), waits=False)
        self.add("*ESE", True, _without_parameters(lambda: str(self.status.ese)), waits=False)
        self.add("*ESR", True, _without_parameters(lambda: str(self.status.read_esr())), waits=False)
        self.add("*SRE", False, self._set_mask("SRE", "sre"), waits=False)
        self.add("*SRE", True, _without_parameters(lambda: str(self.status.sre)), waits=False)
        self.add("*STB", True, _without_parameters(self._status_byte), waits=False)
        self.add("*OPC", False, _without_parameters(self._arm_opc), waits=False)
        self.add("*OPC", True, _without_parameters(lambda: "1"), waits=True)
        self.add("*WAI", False, _without_parameters(lambda: None), waits=True)
        self.add("*TST", True, _without_parameters(lambda: str(self.self_test())), waits=True)
        self.add("SYSTem:ERRor[:NEXT]", True, _without_parameters(self.errors.pop), waits=False)
        self.add("SYSTem:ERRor:COUNt", True, _without_parameters(lambda: str(len(self.errors))), waits=False)
        self.add("SYSTem:VERSion", True, _without_parameters(lambda: SCPI_VERSION), waits=False)
        for name, register in (("OPERation", self.status.operation), ("QUEStionable", self.status.questionable)):
            self._add_register(name, register)
        self.add("STATus:PRESet", False, _without_parameters(self.status.preset), waits=False)
        self.add("SIMulation:TIME", True, _without_parameters(lambda: f"{self.clock.now():.6f}"), waits=False)

    # -- to override -------------------------------------------------------------------
    def identity(self) -> str:  # pragma: no cover - overridden
        raise NotImplementedError

    def reset(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def pending_until(self) -> float | None:
        """Simulated time at which the pending overlapped operations complete, None if none [s]."""
        return None

    def operation_condition(self) -> int:
        """The live STATus:OPERation condition bits (0: nothing in progress)."""
        return 0

    def questionable_condition(self) -> int:
        """The live STATus:QUEStionable condition bits (0: nothing questionable)."""
        return 0

    def self_test(self) -> int:
        """``*TST?`` result: 0 when the self-test passes (IEEE 488.2 10.38)."""
        return 0

    # -- status ------------------------------------------------------------------------
    def _pending(self) -> bool:
        """Whether an overlapped operation is still running at the current simulated time."""
        until = self.pending_until()
        return until is not None and until > self.clock.now()

    def refresh_status(self) -> None:
        """Bring the status registers up to the current simulated time.

        An operation that completed sets the OPC bit of an armed ``*OPC``; the OPERation
        and QUEStionable conditions are re-read and their transitions latched.
        """
        if not self._pending():
            self.status.operations_completed()
        self.status.operation.update(self.operation_condition())
        self.status.questionable.update(self.questionable_condition())

    def complete_pending(self) -> None:
        """Let simulated time pass until the pending overlapped operations have completed."""
        until = self.pending_until()
        if until is not None and until > self.clock.now():
            self.clock.wait_until(until)
        self.refresh_status()

    def _identify(self) -> str:
        self._indefinite_reply = True  # arbitrary ASCII response data (IEEE 488.2 10.14)
        return self.identity()

    def _reset_command(self) -> None:
        """``*RST``: device settings to their defaults, an armed ``*OPC`` cancelled."""
        self.reset()
        self.status.reset()

    def _clear_status(self) -> None:
        """``*CLS``: error queue, SESR and event registers cleared (IEEE 488.2 10.3)."""
        self.errors.clear()
        self.status.clear()

    def _arm_opc(self) -> None:
        self.status.arm_opc(self._pending())

    def _status_byte(self) -> str:
        return str(self.status.status_byte(error_queue_empty=len(self.errors) == 0,
                                           message_available=self._replies_waiting))

    def _set_mask(self, name: str, attribute: str) -> Handler:
        """Handler of ``*ESE <n>`` / ``*SRE <n>``: 0..255, rounded to an integer (IEEE 488.2 10.10, 10.34)."""
        def handler(args: list[str]) -> None:
            expect_args(args, 1)
            value = int(round(parse_number(args[0], name, 0, MASK_8_BIT, 0)))
            if attribute == "sre":
                value &= ~(1 << 6)  # bit 6 of the SRE is ignored (IEEE 488.2 11.3.2.3)
            setattr(self.status, attribute, value)
        return handler

    def _add_register(self, name: str, register) -> None:
        """The SCPI commands of one status register (SCPI-1999 vol. 2, 20)."""
        prefix = f"STATus:{name}"
        self.add(f"{prefix}[:EVENt]", True, _without_parameters(lambda: str(register.read_event())), waits=False)
        self.add(f"{prefix}:CONDition", True, _without_parameters(lambda: str(register.condition)), waits=False)
        for keyword, attribute in (("ENABle", "enable"), ("PTRansition", "ptr"), ("NTRansition", "ntr")):
            self.add(f"{prefix}:{keyword}", False, self._register_setter(f"{prefix}:{keyword}", register, attribute),
                     waits=False)
            self.add(f"{prefix}:{keyword}", True,
                     _without_parameters(lambda attribute=attribute: str(getattr(register, attribute))), waits=False)

    @staticmethod
    def _register_setter(header: str, register, attribute: str) -> Handler:
        def handler(args: list[str]) -> None:
            expect_args(args, 1)
            value = int(round(parse_number(args[0], header, 0, MASK_SCPI_REGISTER, 0)))
            setattr(register, attribute, value)
        return handler

    def add_setting(self, header: str, get: Callable[[], float], put: Callable[[float], None], low: float,
                    high: float, default: float, unit: str | None = None) -> None:
        """Register a numeric setting: ``HEADER <value>`` (a number, with ``unit`` as suffix
        and a multiplier, or ``MIN``/``MAX``/``DEF``, :func:`parse_number`) and ``HEADER?``,
        which with ``MIN``, ``MAX`` or ``DEF`` replies that limit instead of the setting
        (SCPI-1999 vol. 1, 7.2.1: "MINimum|MAXimum" queries)."""
        required = re.sub(r"\[[^]]*\]", "", header).strip(":").split(":")
        name = ":".join("".join(ch for ch in keyword if not ch.islower()) for keyword in required)  # e.g. VOLT

        def put_handler(args: list[str]) -> None:
            expect_args(args, 1)
            put(parse_number(args[0], name, low, high, default, unit))

        def get_handler(args: list[str]) -> str:
            if len(args) > 1:
                raise ScpiError(-108, f"expected at most 1 parameter, got {len(args)}")
            if not args:
                return format_number(get())
            limits = {"MIN": low, "MINIMUM": low, "MAX": high, "MAXIMUM": high, "DEF": default, "DEFAULT": default}
            word = args[0].upper()
            if word not in limits:
                raise ScpiError(-224, f"{name}? takes MIN, MAX or DEF, got '{args[0]}'")
            return format_number(limits[word])

        self.add(header, False, put_handler)
        self.add(header, True, get_handler)

    # -- parameter parsing for subclasses -------------------------------------------------
    @staticmethod
    def parse_integer(text: str, name: str) -> int:
        """Strict integer parameter (see :func:`parse_integer`)."""
        return parse_integer(text, name)

    # -- registration and dispatch ----------------------------------------------------
    def add(self, header: str, query: bool, handler: Handler, waits: bool = True) -> None:
        """Register ``header``: keywords joined by ``:``, long form with the short form in
        capitals, optional nodes in brackets (``[SOURce:]VOLTage[:LEVel]``, :func:`header_keywords`).

        ``waits``: let the pending overlapped operations complete before the command runs
        (every device command; the status and common commands do not wait).
        """
        self._commands.append(_Command(header_keywords(header), query, handler, waits, header))

    def _find(self, tokens: Sequence[str], query: bool, header: str) -> _Command:
        for command in self._commands:
            if command.query == query and _matches(tokens, command.keywords):
                return command
        raise ScpiError(-113, f"{header}{'?' if query else ''}")

    def execute_unit(self, unit: str, path: Sequence[str] = ()) -> str | bytes | None:
        """Execute one message unit (``HEADER[?] [param,...]``); return its reply or None.

        ``path`` is the current path (SCPI-1999 vol. 1, 6.2.4; IEEE 488.2 A.1.1): the nodes
        a header without a leading colon continues from. :meth:`handle_line` keeps it.
        """
        unit = unit.strip()
        match = _UNIT.match(unit)
        if not match:  # e.g. a header with a byte outside printable ASCII
            raise ScpiError(-100, f"'{unit[:40]}'")
        header, question, rest = match.group(1), bool(match.group(2)), match.group(3)
        args = [a.strip() for a in rest.split(",")] if rest is not None and rest.strip() else []
        command = self._find(_header_tokens(header, path), question, header)
        if question and self._indefinite_reply:  # IEEE 488.2 8.7.11: nothing may follow *IDN?'s reply
            raise ScpiError(-440, f"{header}? after *IDN?")
        if command.waits:
            self.complete_pending()
        else:
            self.refresh_status()
        reply = command.handler(args)
        self.refresh_status()  # sample the conditions the command changed (an exposure started)
        return reply

    def handle_line(self, line: str) -> bytes:
        """Process one received line (a program message); return the reply bytes (possibly empty).

        Its units are separated by ``;``. The current path starts at the root; after a
        unit whose header has several nodes it is that header less its last node, so that
        ``STAT:OPER:ENAB 16;PTR 16`` sets ``STAT:OPER:PTR``; a leading ``:`` starts again
        from the root, and common commands (``*CLS``) leave it as it is (SCPI-1999 vol. 1,
        6.2.4; IEEE 488.2 A.1.1). ``MEAS:VOLT?;MEAS:CURR?`` is therefore ``MEAS:MEAS:CURR?``,
        -113, as on a real SCPI instrument; ``MEAS:VOLT?;CURR?`` or ``MEAS:VOLT?;:MEAS:CURR?``
        is meant.
        """
        replies: list[bytes] = []
        self._indefinite_reply = False
        path: tuple[str, ...] = ()
        for unit in line.split(";"):
            if not unit.strip():
                continue
            self._replies_waiting = bool(replies)
            before, path = path, _path_after(unit, path)
            try:
                reply = self.execute_unit(unit, before)
            except ScpiError as error:
                self.errors.push(error)
                continue
            except (ValueError, ArithmeticError) as error:  # e.g. a sample BRDF giving NaN
                self.internal_error(error)
                continue
            if reply is not None:
                replies.append(_reply_bytes(reply))
        self._replies_waiting = False
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

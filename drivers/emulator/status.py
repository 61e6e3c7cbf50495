"""IEEE 488.2 status reporting and the SCPI STATus registers of the emulated SCPI instruments.

The model (docs/protocol.md, "Status reporting") is the one IEEE 488.2 section 11 and
SCPI-1999 vol. 1 section 9 define:

- the **Standard Event Status Register** (SESR, ``*ESR?``, read and cleared) with its enable
  mask (``*ESE``): bit 0 OPC operation complete, 1 RQC request control (never set: a serial
  instrument never asks for control), 2 QYE query error, 3 DDE device-dependent error, 4 EXE
  execution error, 5 CME command error, 6 URQ user request (never set: no front panel), 7 PON
  power on;
- the **Status Byte** (``*STB?``) with the service-request enable mask (``*SRE``): bit 2 the
  error/event queue is not empty (SCPI), bit 3 QUEStionable summary, bit 4 MAV message
  available, bit 5 ESB (SESR and ESE), bit 6 MSS master summary, bit 7 OPERation summary;
- the SCPI **STATus:OPERation** and **STATus:QUEStionable** registers, each a condition
  register (the live state), transition filters (PTR, NTR), a latched event register (read
  and cleared by ``...[:EVENt]?``) and an enable mask feeding the summary bit of the Status
  Byte.

Errors set the SESR bit of their class when they are queued (SCPI-1999 vol. 2, 21.8:
-100..-199 CME, -200..-299 EXE, -300..-399 and device-specific positive codes DDE,
-400..-499 QYE).

References
----------
IEEE Std 488.2-1992, sections 11.2 (Status Byte, MSS, MAV), 11.4 (Standard Event Status
Register, bit definitions 11.5.1), 10.10 to 10.36 (``*CLS``, ``*ESE``, ``*ESR?``, ``*OPC``,
``*RST``, ``*SRE``, ``*STB?``, ``*TST?``, ``*WAI``) and 12 (device/controller
synchronisation: ``*OPC`` and ``*OPC?`` with overlapped commands); SCPI Consortium, "Standard
Commands for Programmable Instruments" 1999.0, vol. 1 section 9 (status reporting model,
status byte bit 2) and vol. 2 section 20 (``STATus`` subsystem, ``STATus:PRESet``) and 21.8
(error classes).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SESR_BITS", "STB_BITS", "OPERATION_BITS", "QUESTIONABLE_BITS", "EventRegister", "StatusModel",
           "error_class_bit"]

#: Standard Event Status Register bits, IEEE 488.2 11.5.1.
SESR_BITS = {"OPC": 0, "RQC": 1, "QYE": 2, "DDE": 3, "EXE": 4, "CME": 5, "URQ": 6, "PON": 7}
#: Status Byte bits, IEEE 488.2 11.2 and SCPI-1999 vol. 1 9.
STB_BITS = {"EAV": 2, "QUES": 3, "MAV": 4, "ESB": 5, "MSS": 6, "OPER": 7}
#: STATus:OPERation bits used by the instruments, SCPI-1999 vol. 2 20.1 (bit 1 SETTling,
#: bit 4 MEASuring).
OPERATION_BITS = {"SETTLING": 1, "MEASURING": 4}
#: STATus:QUEStionable bits used by the instruments, SCPI-1999 vol. 2 20.3 (bit 3 POWer;
#: bit 9 is one of the bits the standard leaves to the designer).
QUESTIONABLE_BITS = {"POWER": 3, "DEVICE": 9}

_REGISTER_MASK = 0x7FFF  # SCPI registers are 16 bits, bit 15 always 0


def error_class_bit(code: int) -> int | None:
    """The SESR bit an error code sets when it is queued (SCPI-1999 vol. 2, 21.8).

    Examples
    --------
    >>> error_class_bit(-113), error_class_bit(-222), error_class_bit(-350), error_class_bit(-410)
    (5, 4, 3, 2)
    >>> error_class_bit(0) is None
    True
    """
    if code == 0:
        return None
    if code > 0 or -399 <= code <= -300:
        return SESR_BITS["DDE"]
    if -199 <= code <= -100:
        return SESR_BITS["CME"]
    if -299 <= code <= -200:
        return SESR_BITS["EXE"]
    if -499 <= code <= -400:
        return SESR_BITS["QYE"]
    return SESR_BITS["DDE"]


@dataclass
class EventRegister:
    """A SCPI status register: condition, transition filters, latched event, enable.

    The condition is the instrument's live state, supplied to :meth:`update`; a change of a
    condition bit latches the event bit when the matching transition filter allows it
    (``ptr`` for 0 -> 1, ``ntr`` for 1 -> 0).  ``STATus:PRESet`` values: ``ptr`` all ones,
    ``ntr`` and ``enable`` zero (SCPI-1999 vol. 2, 20.5).

    Examples
    --------
    >>> r = EventRegister()
    >>> r.update(0b10000); r.update(0)
    >>> r.read_event(), r.read_event()
    (16, 0)
    """

    condition: int = 0
    event: int = 0
    enable: int = 0
    ptr: int = _REGISTER_MASK
    ntr: int = 0

    def update(self, condition: int) -> None:
        """Take the new condition; latch the filtered transitions into the event register."""
        condition &= _REGISTER_MASK
        rising = condition & ~self.condition
        falling = self.condition & ~condition
        self.event |= (rising & self.ptr) | (falling & self.ntr)
        self.condition = condition

    def read_event(self) -> int:
        """The event register, then cleared (``...:EVENt?``)."""
        event, self.event = self.event, 0
        return event

    @property
    def summary(self) -> bool:
        """Whether an enabled event is latched (the register's Status Byte bit)."""
        return bool(self.event & self.enable)

    def preset(self) -> None:
        """``STATus:PRESet``: enable 0, PTR all ones, NTR 0 (events and condition kept)."""
        self.enable, self.ptr, self.ntr = 0, _REGISTER_MASK, 0


class StatusModel:
    """The status registers of one SCPI instrument (see the module docstring).

    Attributes
    ----------
    sesr, ese, sre : int
        Standard Event Status Register, its enable mask, the service-request enable mask.
    operation, questionable : EventRegister
        The SCPI ``STATus:OPERation`` and ``STATus:QUEStionable`` registers.
    opc_armed : bool
        An ``*OPC`` is waiting for the pending operations to complete (Operation Complete
        Command Active State, IEEE 488.2 12.5.2).

    Examples
    --------
    >>> s = StatusModel()
    >>> s.read_esr(), s.read_esr()      # power on, then cleared
    (128, 0)
    >>> s.ese = 0b00100000; s.sre = 0b00100000
    >>> s.record_error(-113)
    >>> s.status_byte(error_queue_empty=False, message_available=False)  # EAV, ESB, MSS
    100
    """

    def __init__(self) -> None:
        self.sesr = 1 << SESR_BITS["PON"]
        self.ese = 0
        self.sre = 0
        self.operation = EventRegister()
        self.questionable = EventRegister()
        self.opc_armed = False

    # -- Standard Event Status Register --------------------------------------------------
    def set_event(self, name: str) -> None:
        """Set one SESR bit by name (``OPC``, ``QYE``, ``DDE``, ``EXE``, ``CME``, ``PON``)."""
        self.sesr |= 1 << SESR_BITS[name]

    def record_error(self, code: int) -> None:
        """An error of ``code`` was queued: set the SESR bit of its class."""
        bit = error_class_bit(code)
        if bit is not None:
            self.sesr |= 1 << bit

    def read_esr(self) -> int:
        """``*ESR?``: the SESR, then cleared (IEEE 488.2 10.12)."""
        value, self.sesr = self.sesr, 0
        return value

    # -- operation complete ----------------------------------------------------------------
    def arm_opc(self, pending: bool) -> None:
        """``*OPC``: set OPC now if nothing is pending, else when it completes."""
        if pending:
            self.opc_armed = True
        else:
            self.set_event("OPC")

    def operations_completed(self) -> None:
        """The pending operations have completed: an armed ``*OPC`` sets OPC."""
        if self.opc_armed:
            self.opc_armed = False
            self.set_event("OPC")

    # -- Status Byte -----------------------------------------------------------------------
    def status_byte(self, error_queue_empty: bool, message_available: bool) -> int:
        """``*STB?``: the Status Byte with MSS in bit 6 (IEEE 488.2 11.2.2.2)."""
        stb = 0
        if not error_queue_empty:
            stb |= 1 << STB_BITS["EAV"]
        if self.questionable.summary:
            stb |= 1 << STB_BITS["QUES"]
        if message_available:
            stb |= 1 << STB_BITS["MAV"]
        if self.sesr & self.ese:
            stb |= 1 << STB_BITS["ESB"]
        if self.operation.summary:
            stb |= 1 << STB_BITS["OPER"]
        if stb & self.sre & ~(1 << STB_BITS["MSS"]):
            stb |= 1 << STB_BITS["MSS"]
        return stb

    # -- clearing --------------------------------------------------------------------------
    def clear(self) -> None:
        """``*CLS``: clear SESR and the event registers, cancel an armed ``*OPC``.

        The enable masks, the transition filters and the conditions are kept (IEEE 488.2
        10.3; SCPI-1999 vol. 2, 20).
        """
        self.sesr = 0
        self.operation.event = 0
        self.questionable.event = 0
        self.opc_armed = False

    def reset(self) -> None:
        """``*RST``: cancel an armed ``*OPC`` only; every status register is kept (IEEE 488.2 10.32)."""
        self.opc_armed = False

    def preset(self) -> None:
        """``STATus:PRESet``: the OPERation and QUEStionable enables and filters to their preset values."""
        self.operation.preset()
        self.questionable.preset()

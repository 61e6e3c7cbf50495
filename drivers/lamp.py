"""Driver for the rig's lamp power supply (SCPI over 9600 8N1, LF terminators).

Commands (docs/protocol.md): ``OUTP ON|OFF``/``OUTP?``, ``VOLT <V>``/``VOLT?`` (setpoint
[V]), ``MEAS:VOLT?``/``MEAS:CURR?`` (measured output [V], [A]), ``STAT:LAMP?`` (``OK`` or
``FAULT``, e.g. a burnt-out filament), plus the IEEE 488.2 common commands.
"""
from __future__ import annotations

from .errors import LampError, ProtocolError
from .scpi import ScpiInstrument

__all__ = ["Lamp"]


def _parse_on_off(reply: str) -> bool:
    value = reply.strip().upper()
    if value in ("1", "ON"):
        return True
    if value in ("0", "OFF"):
        return False
    raise ValueError(f"expected ON/OFF or 1/0, got {reply!r}")


class Lamp(ScpiInstrument):
    """Client of the lamp power supply.

    Examples
    --------
    >>> lamp = Lamp.open("gonio-sim://lamp?rig=lab")     # doctest: +SKIP
    >>> lamp.set_voltage(100.0); lamp.output_on()        # doctest: +SKIP
    >>> lamp.measured_current()                          # doctest: +SKIP
    2.49
    """

    BAUDRATE = 9600
    DEVICE = "lamp"
    ERROR = LampError

    def output_on(self, check: bool | None = None) -> None:
        """Switch the output on (``OUTP ON``)."""
        self.write("OUTP ON", check)

    def output_off(self, check: bool | None = None) -> None:
        """Switch the output off (``OUTP OFF``)."""
        self.write("OUTP OFF", check)

    def output_is_on(self) -> bool:
        """True if the output is on (``OUTP?``)."""
        return self.query("OUTP?", _parse_on_off)

    def voltage_setpoint(self) -> float:
        """Voltage setpoint (``VOLT?``) [V]."""
        return self.query("VOLT?", float)

    def set_voltage(self, volts: float, check: bool | None = None) -> None:
        """Set the voltage setpoint (``VOLT``) [V]; the supply checks the range (-222)."""
        self.write(f"VOLT {float(volts):.6g}", check)

    def measured_voltage(self) -> float:
        """Measured output voltage (``MEAS:VOLT?``) [V]."""
        return self.query("MEAS:VOLT?", float)

    def measured_current(self) -> float:
        """Measured output current (``MEAS:CURR?``) [A]."""
        return self.query("MEAS:CURR?", float)

    def lamp_status(self) -> str:
        """``"OK"`` or ``"FAULT"`` (``STAT:LAMP?``)."""
        status = self.query("STAT:LAMP?", lambda r: r.strip().upper())
        if status not in ("OK", "FAULT"):
            raise ProtocolError(f"lamp: unexpected STAT:LAMP? reply {status!r}")
        return status

    def check_lamp(self) -> None:
        """Raise :class:`LampError` if the supply reports a lamp fault."""
        if self.lamp_status() != "OK":
            raise LampError(0, "lamp fault (STAT:LAMP? -> FAULT): filament open or burnt out", "STAT:LAMP?")

"""Firmware of the emulated lamp power supply (SCPI dialect of docs/protocol.md, section 3)."""
from __future__ import annotations

import numpy as np

from .clock import SimClock
from .lamp import Lamp
from .scpi import ScpiError, ScpiInstrument, expect_args
from .status import OPERATION_BITS, QUESTIONABLE_BITS

__all__ = ["LampFirmware"]


class LampFirmware(ScpiInstrument):
    """SCPI command set of the lamp power supply driving a :class:`~drivers.emulator.lamp.Lamp`.

    Status (docs/protocol.md, "Status reporting"): STATus:OPERation bit 1 (SETTling) while
    the output is on and the lamp has not yet settled (:meth:`Lamp.settled
    <drivers.emulator.lamp.Lamp.settled>`); STATus:QUEStionable bit 3 (POWer) while the output
    is on and the light is not stable (warming up or burnt out) and bit 9 while the lamp is
    burnt out; ``*TST?`` replies 1 for a burnt-out lamp.  No command is overlapped.

    Parameters
    ----------
    clock : SimClock
        Shared simulated clock.
    lamp : Lamp
        The lamp (shared with the scene, which reads its output).
    rng : numpy.random.Generator
        Read-back noise source.
    serial : str
        Serial number in ``*IDN?``.
    """

    def __init__(self, clock: SimClock, lamp: Lamp, rng: np.random.Generator, serial: str = "SN0001") -> None:
        super().__init__()
        self.clock = clock
        self.lamp = lamp
        self.rng = rng
        self.serial = serial
        self.add("OUTPut[:STATe]", False, self._set_output)
        self.add("OUTPut[:STATe]", True, lambda a: expect_args(a, 0) or ("1" if self.lamp.on else "0"))
        p = lamp.params
        self.add_setting("[SOURce:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", lambda: self.lamp.voltage_setpoint_v,
                         self.lamp.set_voltage, 0.0, p.max_voltage_v, p.nominal_voltage_v, unit="V")
        self.add("MEASure[:SCALar]:VOLTage[:DC]", True, self._measure_voltage)
        self.add("MEASure[:SCALar]:CURRent[:DC]", True, self._measure_current)
        self.add("STATus:LAMP", True, lambda a: expect_args(a, 0) or ("FAULT" if self.lamp.burnt_out else "OK"))
        self.add("*OPT", True, lambda a: expect_args(a, 0) or "0", waits=False)

    def operation_condition(self) -> int:
        """Bit 1 (SETTling) while the output is on and the lamp is still warming up."""
        lamp = self.lamp
        settling = lamp.on and not lamp.burnt_out and not lamp.settled(self.clock.now())
        return (1 << OPERATION_BITS["SETTLING"]) if settling else 0

    def questionable_condition(self) -> int:
        """Bit 3 (POWer) while the light of a lamp that is on is not stable; bit 9 while burnt out."""
        lamp = self.lamp
        bits = (1 << QUESTIONABLE_BITS["DEVICE"]) if lamp.burnt_out else 0
        if lamp.on and (lamp.burnt_out or not lamp.settled(self.clock.now())):
            bits |= 1 << QUESTIONABLE_BITS["POWER"]
        return bits

    def self_test(self) -> int:
        """1 for a burnt-out lamp, else 0."""
        return 1 if self.lamp.burnt_out else 0

    def identity(self) -> str:
        return f"GONIO,LPS-300,{self.serial},1.0"

    def reset(self) -> None:
        self.lamp.switch(False, self.clock.now())
        self.lamp.set_voltage(self.lamp.params.nominal_voltage_v)

    def _set_output(self, args: list[str]) -> None:
        expect_args(args, 1)
        word = args[0].upper()
        if word in ("ON", "1"):
            self.lamp.switch(True, self.clock.now())
        elif word in ("OFF", "0"):
            self.lamp.switch(False, self.clock.now())
        else:
            raise ScpiError(-104, f"OUTP expects ON or OFF, got '{args[0]}'")  # escaped when queued

    def _measure_voltage(self, args: list[str]) -> str:
        expect_args(args, 0)
        v = self.lamp.voltage()
        noisy = v * (1.0 + self.lamp.params.voltage_noise_rms * self.rng.standard_normal()) if v else 0.0
        return f"{noisy:.3f}"

    def _measure_current(self, args: list[str]) -> str:
        expect_args(args, 0)
        i = self.lamp.current(self.clock.now())
        noisy = i * (1.0 + self.lamp.params.current_noise_rms * self.rng.standard_normal()) if i else 0.0
        return f"{noisy:.4f}"

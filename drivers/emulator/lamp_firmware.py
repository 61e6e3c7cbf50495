"""Firmware of the emulated lamp power supply (SCPI dialect of docs/protocol.md, section 3)."""
from __future__ import annotations

import numpy as np

from .clock import SimClock
from .lamp import Lamp
from .scpi import ScpiError, ScpiInstrument, expect_args, format_number, parse_number

__all__ = ["LampFirmware"]


class LampFirmware(ScpiInstrument):
    """SCPI command set of the lamp power supply driving a :class:`~drivers.emulator.lamp.Lamp`.

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
        self.add("OUTPut", False, self._set_output)
        self.add("OUTPut", True, lambda a: expect_args(a, 0) or ("1" if self.lamp.on else "0"))
        self.add("VOLTage", False, self._set_voltage)
        self.add("VOLTage", True, lambda a: expect_args(a, 0) or format_number(self.lamp.voltage_setpoint_v))
        self.add("MEASure:VOLTage", True, self._measure_voltage)
        self.add("MEASure:CURRent", True, self._measure_current)
        self.add("STATus:LAMP", True, lambda a: expect_args(a, 0) or ("FAULT" if self.lamp.burnt_out else "OK"))

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

    def _set_voltage(self, args: list[str]) -> None:
        expect_args(args, 1)
        p = self.lamp.params
        self.lamp.set_voltage(parse_number(args[0], "VOLT", 0.0, p.max_voltage_v, p.nominal_voltage_v))

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

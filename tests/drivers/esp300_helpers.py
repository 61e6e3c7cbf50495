"""Helpers shared by the ESP300 firmware tests: talk to a firmware object line by line."""
from __future__ import annotations

from drivers.emulator.stage_firmware import Esp300Firmware


def ask(fw: Esp300Firmware, line: str) -> str:
    """The firmware's reply to one command line, as text."""
    return fw.handle_line(line).decode("ascii")


def errors(fw: Esp300Firmware) -> list[int]:
    """Every queued error code (TE? until 0), oldest first."""
    codes = []
    while (code := int(ask(fw, "TE?"))) != 0:
        codes.append(code)
    return codes

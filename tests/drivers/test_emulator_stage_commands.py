"""ESP300 commands stock drivers send (pymeasure, InstrumentKit): exact command/reply pairs.

Manual references are to the Newport ESP300 User's Manual (docs/protocol.md section 1,
"Commands").
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.emulator.clock import SimClock
from esp300_helpers import ask, errors
from drivers.emulator.stage_firmware import MAX_COMMAND_LINE, Esp300Firmware, move_duration


def make_stage(seed: int = 0) -> Esp300Firmware:
    return Esp300Firmware(SimClock(), np.random.default_rng(seed))


def test_stage_identification():  # manual p. 3-86
    fw = make_stage()
    assert ask(fw, "1ID?;2ID?;3ID?") == "GONIO-SWING, SN0101\r\nGONIO-POLAR, SN0102\r\nGONIO-AZIMUTH, SN0103\r\n"
    assert ask(fw, "ID?;7ID?;1ID") == ""
    assert errors(fw) == [37, 9, 6]


@pytest.mark.parametrize("line", ["*IDN?", "*OPC?", "*STB?", "*OPT?", "SYST:ERR?", "*RST", "*CLS"])
def test_ieee488_common_commands_do_not_exist_on_an_esp300(line):
    """Not of the manual's syntax [xx]AA[nn] (3.4.1): COMMAND DOES NOT EXIST, no reply."""
    fw = make_stage()
    assert ask(fw, line) == ""
    assert ask(fw, "TB?").startswith("6, ") and errors(fw) == []


def test_command_line_longer_than_80_characters_executes_nothing():  # manual 3.4.1, p. 3-8
    fw = make_stage()
    line = "1MO;" + ";".join(["1VA?"] * 15) + "  "
    assert len(line) == MAX_COMMAND_LINE and ask(fw, line) == "10.00000\r\n" * 15
    assert ask(fw, "1MF;" + line[4:] + " ") == ""  # 81 characters: not even 1MF runs
    assert errors(fw) == [6] and ask(fw, "1MO?") == "1\r\n"


def test_define_home_shifts_the_coordinates():
    fw = make_stage()
    ask(fw, "1MO;1PA30;1WS")
    ask(fw, "1DH")
    assert ask(fw, "1TP;1DP?;1DH?") == "0.00000\r\n0.00000\r\n0.00000\r\n"
    ask(fw, "1PA-10;1WS")  # 10 deg back: mechanically at 20 deg
    assert fw.true_positions()[0] == pytest.approx(20.0, abs=0.01)
    ask(fw, "1DH5")
    assert ask(fw, "1TP;1DH?") == "5.00000\r\n5.00000\r\n"
    ask(fw, "1PA20")
    assert ask(fw, "1DH") == "" and errors(fw) == [27]  # not while moving
    ask(fw, "1WS;1OR;1WS")  # the home switch (mechanical 0 deg) is given the DH value
    assert fw.true_positions()[0] == pytest.approx(0.0, abs=0.01)
    assert float(ask(fw, "1TP")) == pytest.approx(5.0, abs=0.01)
    assert errors(fw) == []


def test_deceleration_is_separate_from_acceleration():
    fw = make_stage()
    ask(fw, "MO;1AC20;1AG10")
    assert ask(fw, "1AC?;1AG?") == "20.00000\r\n10.00000\r\n"
    t0 = fw.clock.now()
    ask(fw, "1PA30;1WS")
    assert fw.clock.now() - t0 == pytest.approx(move_duration(30.0, 10.0, 20.0, 10.0), abs=1e-3)  # 3.75 s
    assert ask(fw, "1AG0;1AG100") == "" and errors(fw) == [101, 111]  # below 0.001, above AU = 80


def test_maximum_velocity_and_acceleration_bound_the_settings():
    fw = make_stage()
    assert ask(fw, "1VU?;1AU?") == "20.00000\r\n80.00000\r\n"
    ask(fw, "1VU5;1AU10")
    assert ask(fw, "1VA?;1AC?;1AG?;1AE?") == "5.00000\r\n10.00000\r\n10.00000\r\n10.00000\r\n"
    assert ask(fw, "1VA6;1AC11;1VU30;1AU81") == ""
    assert errors(fw) == [110, 111, 110, 111]  # VU, AU: up to the stage's own maxima (20, 80)


def test_abort_stops_with_the_estop_deceleration_and_switches_the_motors_off():
    fw = make_stage()
    ask(fw, "MO;1AE80;1PA80")
    fw.clock.advance(2.0)  # cruising at 10 deg/s
    ask(fw, "AB")
    assert ask(fw, "1MO?;1MD?") == "0\r\n0\r\n"
    fw.clock.advance(10.0 / 80.0 + 1e-6)  # v / AE
    assert ask(fw, "1MD?") == "1\r\n"
    stopped = fw.true_positions()[0]
    assert float(ask(fw, "1DP?")) == pytest.approx(stopped, abs=1e-3)
    assert ask(fw, "1PA0") == "" and errors(fw) == [113]


def test_wait_for_position_holds_until_the_axis_passes_it():
    fw = make_stage()
    ask(fw, "1MO;1PA30;1WP15")
    assert fw.clock.now() == pytest.approx(1.75, abs=1e-3)  # symmetric 3.5 s move: half way
    assert float(ask(fw, "1TP")) == pytest.approx(15.0, abs=2e-3)
    ask(fw, "1WP60")  # never reached: the emulator waits until the axis stops
    assert ask(fw, "1MD?") == "1\r\n" and errors(fw) == []


def test_reset_restores_the_power_on_state():
    fw = make_stage()
    ask(fw, "MO;1VA5;1SN9;1PA0.5;1WS;1DH0;FOO")
    ask(fw, "RS")
    assert ask(fw, "1VA?;1MO?;1SN?;1DH?;TE?") == "10.00000\r\n0\r\n7\r\n0.00000\r\n0\r\n"
    assert float(ask(fw, "1TP")) == pytest.approx(math.degrees(0.5), abs=2e-3)  # mechanical angle


def test_angular_units_scale_every_quantity():
    fw = make_stage()
    ask(fw, "1MO;1SN9;1PA0.5;1WS")
    assert fw.true_positions()[0] == pytest.approx(math.degrees(0.5), abs=0.01)
    assert float(ask(fw, "1TP")) == pytest.approx(0.5, abs=1e-4)
    assert ask(fw, "1SN?;1VA?") == f"9\r\n{math.radians(10.0):.5f}\r\n"
    ask(fw, "1SN0")  # encoder counts of 0.001 deg
    assert ask(fw, "1SU?;1PA?") == f"1.00000\r\n{math.degrees(0.5) * 1000:.5f}\r\n"
    assert ask(fw, "1SN2;1SN7.5;1SN12") == "" and errors(fw) == [101, 101, 101]  # linear, not a code
    assert ask(fw, "1SN?") == "0\r\n"

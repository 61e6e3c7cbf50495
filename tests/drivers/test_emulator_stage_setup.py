"""ESP300 motor and servo settings, moves to a limit and stored programs: command/reply pairs.

The commands behind InstrumentKit's ``setup_axis``/``read_setup``, ``move_to_hardware_limit``,
``move_indefinitely`` and programs (docs/protocol.md section 1, "Motor and servo settings",
"Moves to a limit", "Stored programs").
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.clock import SimClock
from esp300_helpers import ask, errors
from drivers.emulator.stage_firmware import PROGRAM_MEMORY, Esp300Firmware


def make_stage(seed: int = 0) -> Esp300Firmware:
    return Esp300Firmware(SimClock(), np.random.default_rng(seed))


def test_power_on_settings():
    fw = make_stage()
    lines = ("1QM?;1QI?;1QV?;1KP?;1KI?;1KD?;1KS?;1AF?;1FE?;1JK?", "1JH?;1JW?;1VB?;1FR?;1FP?;1TJ?;1QS?;1ZB?;1ZH?;1QR?")
    assert "".join(ask(fw, line) for line in lines).split("\r\n")[:-1] == [
        "1", "1.00000", "24.00000", "0.00500", "0.00010", "0.02000", "0.50000", "0.00000", "1.00000",
        "800.00000", "10.00000", "2.00000", "0.00000", "0.00100", "3", "1", "10", "110H", "24H", "0, 0"]


@pytest.mark.parametrize("command, query, reply", [
    ("1KP0.25", "1KP?", "0.25000"), ("1KP2e9", "1KP?", "2000000000.00000"), ("1QI3", "1QI?", "3.00000"),
    ("1QV48", "1QV?", "48.00000"), ("1FE0.5", "1FE?", "0.50000"), ("1JK1000", "1JK?", "1000.00000"),
    ("1JH20", "1JH?", "20.00000"), ("1QS250", "1QS?", "250"), ("1FP7", "1FP?", "7"),
    ("1ZB0F25H", "1ZB?", "F25H"), ("1ZB123", "1ZB?", "123H"), ("1ZH0", "1ZH?", "0H"),
    ("1QR60000,100", "1QR?", "60000, 100"), ("1QM0", "1QM?", "0"),
])
def test_settings_are_stored_and_read_back(command, query, reply):
    fw = make_stage()
    assert ask(fw, f"{command};{query}") == reply + "\r\n"
    assert errors(fw) == []


@pytest.mark.parametrize("command, code", [
    ("1KP-1", 101), ("1KP3e9", 101), ("1QI3.5", 101), ("1QV-1", 101), ("1QS0", 101), ("1QS2.5", 101),
    ("1QM2", 101), ("1TJ7", 101), ("1TJ0", 101), ("1FP8", 101), ("1JH21", 110), ("1JW0", 101), ("1FE0", 101),
    ("1ZBF25H", 6), ("1ZB0G", 101), ("1ZB10000H", 101), ("1QR60001,5", 101), ("1QR5", 38),
    ("1KP", 38), ("KP1", 37), ("4KP1", 9),
])
def test_out_of_range_settings_are_refused_and_change_nothing(command, code):
    fw = make_stage()
    mnemonic = command.lstrip("0123456789")[:2]
    before = ask(fw, f"1{mnemonic}?")
    ask(fw, command)
    assert errors(fw) == [code]
    assert ask(fw, f"1{mnemonic}?") == before


def test_settings_follow_the_axis_units_and_a_lowered_maximum_velocity():
    fw = make_stage()
    ask(fw, "1FE0.9;1SN8")  # gradians: 0.9 deg each
    assert ask(fw, "1FE?;1JH?") == "1.00000\r\n11.11111\r\n"
    ask(fw, "1SN7;1VU5")
    assert ask(fw, "1JH?;1JW?") == "5.00000\r\n2.00000\r\n"


def test_sm_saves_the_settings_that_rs_loads():
    fw = make_stage()
    ask(fw, "1KP0.3;1VA12;SM;1KP0.4;1VA15;RS")
    assert ask(fw, "1KP?;1VA?") == "0.30000\r\n12.00000\r\n"
    assert ask(fw, "UF;1UF?;1QD5") == ""
    assert errors(fw) == [37, 6, 6]


def test_undefined_motor_type_refuses_moves():
    fw = make_stage()
    ask(fw, "1QM0;1MO;1PA10;1MT;1MV;1QM1;1PA10;1WS")
    assert errors(fw) == [100, 100, 100]
    assert float(ask(fw, "1TP")) == pytest.approx(10.0, abs=0.01)


def test_mt_moves_onto_the_hardware_limit_past_the_software_limit():
    fw = make_stage()
    ask(fw, "2MO;2MT-")
    assert ask(fw, "2MT?") == "0\r\n"
    ask(fw, "2WS")
    assert ask(fw, "2MT?;2TP;2DP?") == "1\r\n-3.00000\r\n-3.00000\r\n"
    assert fw.true_positions()[1] == -3.0
    assert errors(fw) == []  # reaching the switch is the end of the command, not an error
    ask(fw, "2MT+;2WS")
    assert ask(fw, "2TP") == "93.00000\r\n"
    ask(fw, "2MTx;2MT")
    assert errors(fw) == [201]


def test_mv_runs_until_stopped_or_until_the_software_limit():
    fw = make_stage()
    ask(fw, "1MO;1MV-")
    fw.clock.wait_until(fw.clock.now() + 2.0)
    assert ask(fw, "1MV?") == "0\r\n"
    ask(fw, "1ST;1WS")
    stopped = float(ask(fw, "1TP"))
    assert -90.0 < stopped < 0.0 and ask(fw, "1MV?") == "1\r\n"
    assert float(ask(fw, "1DP?")) == pytest.approx(stopped, abs=0.002)
    ask(fw, "1MV-;1WS")
    assert ask(fw, "1TP") == "-90.00000\r\n"
    assert errors(fw) == [107]
    ask(fw, "1MV-")  # already at the limit
    assert errors(fw) == [107]
    ask(fw, "1MV+;1PA3;AB")  # moving: PA refused (27); AB stops it and the motors
    assert errors(fw) == [27]
    assert ask(fw, "1MO?") == "0\r\n"


def test_program_entry_execution_listing_and_erasing():
    fw = make_stage()
    ask(fw, "1MO;2MO")
    assert ask(fw, "7EP;1PA20;1WS;1TP;2PR10;2WS;QP") == ""  # stored, unevaluated, no reply
    assert fw.true_positions() == (0.0, 45.0, 0.0)
    assert ask(fw, "7LP") == "1PA20\r\n1WS\r\n1TP\r\n2PR10\r\n2WS\r\n"
    reply = ask(fw, "7EX;2TP")
    assert [round(float(v), 1) for v in reply.split()] == [20.0, 55.0]
    ask(fw, "7EP")  # exists: erase first
    ask(fw, "7XX;7LP;7EX;101EP;EP")
    assert errors(fw) == [27, 27, 27, 7, 37]


def test_program_text_is_not_evaluated_until_run():
    fw = make_stage()
    ask(fw, "3EP;TB?;1PA500;QP")  # a query in program entry mode is stored, not answered
    assert ask(fw, "TB?").startswith("0, ")
    assert ask(fw, "3EX").startswith("0, ")  # the stored TB? answers when the program runs
    assert errors(fw) == [113]  # 1PA500 of the program: motor off


def test_a_program_cannot_start_a_program_and_memory_is_bounded():
    fw = make_stage()
    ask(fw, "1EP;1EX;2EP;QP")
    ask(fw, "1EX")
    assert errors(fw) == [27, 27]  # EX and EP inside program 1
    ask(fw, "4EP")
    chunk = ";".join(["1PA1"] * 15)
    for _ in range(PROGRAM_MEMORY // (5 * 15) + 1):
        fw.handle_line(chunk)
    ask(fw, "QP")
    assert errors(fw)[:1] == [27]
    ask(fw, "6EP;1TP;QP")  # memory full: not stored
    assert errors(fw) == [27] and ask(fw, "6LP") == ""
    ask(fw, "4XX;6XX;6EP;1TP;QP")  # erasing frees the memory
    assert ask(fw, "6LP") == "1TP\r\n" and errors(fw) == [27]  # 27: the earlier 6LP of an empty program
    assert ask(fw, "RS;5EP;QP;5LP") == ""  # RS ends program entry mode; programs are kept
    assert ask(fw, "1LP") == "1EX\r\n2EP\r\n"

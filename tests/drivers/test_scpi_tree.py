"""The SCPI parser walks the command tree (drivers/emulator/scpi.py; SCPI-1999 vol. 1
section 6 and 7.2, IEEE 488.2 7.7, 8.7 and A.1): the current path after ';', optional
nodes, suffix units with multipliers, MIN/MAX/DEF in queries and IEEE 488.2's numeric
response forms. The cases are the standard's own examples and those instrument manuals
give for it (e.g. 'MEAS:VOLT?;CURR?', ':DISP:FORM DIG;RES 2' as ':DISP:FORM DIG;:DISP:RES 2')."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.rig import EmulatedRig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1 / np.pi)


@pytest.fixture
def rig():
    return EmulatedRig(lambert, seed=5, lamp_warm=True, motors_on=True)


def ask(rig, device, line):
    return rig.channels[device].process(line).decode("ascii")


def errors(rig, device):
    out = []
    while not (reply := ask(rig, device, ":SYST:ERR?")).startswith("0,"):
        out.append(int(reply.split(",")[0]))
    return out


# -- the current path (SCPI-1999 vol. 1, 6.2.4; IEEE 488.2 A.1.1) -------------------------
def test_a_unit_after_a_semicolon_continues_from_the_previous_headers_node(rig):
    ask(rig, "camera", "STAT:OPER:ENAB 16;PTR 16;NTR 4")
    assert ask(rig, "camera", "STAT:OPER:ENAB?;PTR?;NTR?") == "16;16;4\n"
    assert errors(rig, "camera") == []
    assert ask(rig, "lamp", "MEAS:VOLT?;CURR?").count(";") == 1  # MEASure:CURRent, not a root CURRent


def test_repeating_the_subsystem_after_a_semicolon_is_an_undefined_header(rig):
    """'MEAS:VOLT?;MEAS:CURR?' is MEAS:MEAS:CURR? to a SCPI instrument: -113, the first
    reply kept; a leading colon starts from the root again."""
    assert ask(rig, "lamp", "MEAS:VOLT?;MEAS:CURR?").count(";") == 0
    assert errors(rig, "lamp") == [-113]
    assert ask(rig, "lamp", "MEAS:VOLT?;:MEAS:CURR?").count(";") == 1
    assert errors(rig, "lamp") == []


def test_common_commands_leave_the_path_and_a_new_line_starts_at_the_root(rig):
    assert ask(rig, "camera", "STAT:OPER:ENAB 8;*CLS;PTR 2;*ESE?") == "0\n"
    assert ask(rig, "camera", "STAT:OPER:PTR?") == "2\n"  # a new program message: from the root
    assert ask(rig, "camera", "EXP 0.02;GAIN 2;EXP?;GAIN?") == "0.02;2\n"  # root-level nodes: the path stays the root
    assert errors(rig, "camera") == []


# -- optional nodes (SCPI-1999 vol. 1, 6.2.5) -----------------------------------------------
@pytest.mark.parametrize("line", ["SOUR:VOLT 100", "VOLT:LEV 100", "SOURCE:VOLTAGE:LEVEL:IMMEDIATE:AMPLITUDE 100",
                                  "VOLT:LEV:IMM 100", ":SOUR:VOLT:AMPL 100"])
def test_optional_nodes_may_be_given_or_left_out(rig, line):
    ask(rig, "lamp", line)
    assert ask(rig, "lamp", "SOUR:VOLT?") == "100\n"
    assert ask(rig, "lamp", "VOLT?") == "100\n"
    assert errors(rig, "lamp") == []


def test_optional_nodes_of_output_measure_and_the_error_queue(rig):
    ask(rig, "lamp", "OUTP:STAT ON")
    assert ask(rig, "lamp", "OUTP:STAT?;:OUTP?") == "1;1\n"
    assert float(ask(rig, "lamp", "MEAS:VOLT:DC?")) > 100.0
    assert float(ask(rig, "lamp", "MEAS:SCAL:CURR:DC?")) > 0.0
    ask(rig, "lamp", "BOGUS")
    assert ask(rig, "lamp", "SYST:ERR:NEXT?").startswith("-113,")
    ask(rig, "lamp", "VOLT:LEV:LEV 100")  # a node given twice is not an optional node
    assert errors(rig, "lamp") == [-113]


# -- numbers with suffixes (IEEE 488.2 7.7.3; SCPI-1999 vol. 1, 7.2.3) ----------------------
@pytest.mark.parametrize("value, seconds", [("25 ms", 0.025), ("25MS", 0.025), ("0.5 s", 0.5), ("200 us", 2e-4),
                                            ("1.5e3 ms", 1.5)])
def test_an_exposure_takes_seconds_with_a_multiplier(rig, value, seconds):
    ask(rig, "camera", f"EXP {value}")
    assert float(ask(rig, "camera", "EXP?")) == pytest.approx(seconds)
    assert errors(rig, "camera") == []


@pytest.mark.parametrize("device, line, code", [
    ("camera", "EXP 25 V", -131),       # the wrong unit
    ("camera", "EXP 25 XS", -131),      # no such multiplier
    ("camera", "GAIN 2 dB", -138),      # a gain takes no suffix
    ("lamp", "VOLT 110 S", -131),
])
def test_a_wrong_or_unexpected_suffix_is_refused_and_nothing_changes(rig, device, line, code):
    header = line.split()[0]
    before = ask(rig, device, f"{header}?")
    ask(rig, device, line)
    assert errors(rig, device) == [code]
    assert ask(rig, device, f"{header}?") == before


def test_volts_with_a_multiplier(rig):
    ask(rig, "lamp", "VOLT 0.1 KV")
    assert ask(rig, "lamp", "VOLT?") == "100\n"
    ask(rig, "lamp", "VOLT 110000 MV")  # M is milli (IEEE 488.2 table 7-2)
    assert ask(rig, "lamp", "VOLT?") == "110\n"


# -- MINimum / MAXimum / DEFault (SCPI-1999 vol. 1, 7.2.1) ------------------------------------
def test_min_max_and_def_in_queries_reply_the_limits(rig):
    assert ask(rig, "camera", "EXP? MAX;EXP? MIN;EXP? DEF") == "60;1.0E-05;0.01\n"
    assert ask(rig, "camera", "GAIN? MIN;GAIN? maximum") == "1;16\n"
    assert ask(rig, "lamp", "VOLT? MAX;VOLT? DEF") == "132;120\n"
    ask(rig, "camera", "EXP? LOUD")
    assert errors(rig, "camera") == [-224]
    assert ask(rig, "camera", "EXP?") == "0.01\n"  # the setting itself is unchanged


# -- numeric response forms (IEEE 488.2 8.7.2-8.7.4) ---------------------------------------
def test_small_numbers_are_sent_in_nr3_with_an_explicit_point_and_exponent(rig):
    ask(rig, "camera", "EXP MIN")
    assert ask(rig, "camera", "EXP?") == "1.0E-05\n"
    ask(rig, "camera", "EXP 2.5e-05")
    assert ask(rig, "camera", "EXP?") == "2.5E-05\n"

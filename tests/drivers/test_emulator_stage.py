"""Emulated ESP300 motion controller: exact command/reply pairs at the firmware level.

Reference: Newport ESP300 User's Manual, section 3 (command syntax 3.4.1, TE/TB, PA, MD,
WS, ...) and Appendix A (error codes); the emulator's subset is docs/protocol.md section 1.
"""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.emulator.clock import SimClock
from esp300_helpers import ask, errors
from drivers.emulator.stage_firmware import Esp300Firmware, move_duration, profile_from_state
from drivers.emulator.world import separation_deg


def make_stage(min_sep: float | None = 5.0, seed: int = 0) -> Esp300Firmware:
    def interlock(positions):
        return separation_deg(*positions) >= min_sep

    return Esp300Firmware(SimClock(), np.random.default_rng(seed), interlock=interlock if min_sep else None)


def test_identity_and_power_on_state():
    fw = make_stage()
    assert ask(fw, "VE?") == "ESP300 Version 3.08 09/09/02\r\n"
    assert ask(fw, "VE") == ask(fw, "VE?")
    # Power-on: motors off, every axis at home (1: 0, 2: 45, 3: 0), units degrees (SN 7).
    assert ask(fw, "1MO?;2MO?;3MO?") == "0\r\n0\r\n0\r\n"
    assert ask(fw, "1TP;2TP;3TP") == "0.00000\r\n45.00000\r\n0.00000\r\n"
    assert ask(fw, "1SN?") == "7\r\n"
    assert ask(fw, "TE?") == "0\r\n"
    assert re.fullmatch(r"0, \d+, NO ERROR DETECTED\r\n", ask(fw, "TB?"))


def test_move_refused_while_motor_off_then_accepted():
    fw = make_stage()
    assert ask(fw, "1PA30") == ""
    assert errors(fw) == [113]  # axis 1, MOTOR NOT ENABLED
    assert ask(fw, "1TP") == "0.00000\r\n"  # nothing moved
    ask(fw, "MO")  # without axis: all motors on
    assert ask(fw, "1MO?;2MO?;3MO?") == "1\r\n1\r\n1\r\n"
    assert ask(fw, "1PA30;1WS;1MD?") == "1\r\n"
    # Repeatability 0.002 deg (1 sigma) and 0.001 deg encoder resolution: within 0.01 deg.
    assert abs(float(ask(fw, "1TP")) - 30.0) < 0.01
    assert ask(fw, "1DP?") == "30.00000\r\n"
    assert ask(fw, "1PA?") == "30.00000\r\n"


def test_trapezoidal_profile_timing_and_intermediate_positions():
    fw = make_stage()
    ask(fw, "1MO")
    t0 = fw.clock.now()
    ask(fw, "1PA30")  # v = 10 deg/s, a = 20 deg/s^2: 0.5 s ramps, total 30/10 + 10/20 = 3.5 s
    fw.clock.wait_until(t0 + 1.0)
    assert ask(fw, "1MD?") == "0\r\n"
    # At 1.0 s: 0.5 * 20 * 0.5^2 + 10 * 0.5 = 7.5 deg (exact up to the 0.002 deg end-point scatter,
    # scaled by 7.5/30, and the 0.001 deg encoder step).
    assert abs(float(ask(fw, "1TP")) - 7.5) < 0.003
    ask(fw, "1WS")
    assert fw.clock.now() == pytest.approx(t0 + 3.5, abs=1e-3)
    assert move_duration(1.25, 10.0, 20.0) == pytest.approx(0.5)  # triangular: 2 sqrt(d/a)


def test_axis_prefix_forms_blanks_case_and_separators():
    fw = make_stage()
    ask(fw, "01mo ; 2 MO")
    assert ask(fw, "01MO?;2mo?") == "1\r\n1\r\n"
    ask(fw, " 1 pa 10 ;1WS")
    assert abs(float(ask(fw, "1 TP ?")) - 10.0) < 0.01
    ask(fw, "1pa-1.5e1;1ws")
    assert abs(float(ask(fw, "1TP")) + 15.0) < 0.01
    assert ask(fw, "") == "" and errors(fw) == []


def test_relative_move_and_home():
    fw = make_stage()
    ask(fw, "MO;1PA20;1WS;1PR-5;1WS")
    assert ask(fw, "1DP?") == "15.00000\r\n"
    ask(fw, "1OR;1WS")
    assert ask(fw, "1DP?") == "0.00000\r\n"
    ask(fw, "1OR9")
    assert errors(fw) == [101]  # homing mode must be 0..6


def test_software_limits_refuse_and_leave_axis_in_place():
    fw = make_stage()
    ask(fw, "MO")
    assert ask(fw, "1SL?;1SR?") == "-90.00000\r\n90.00000\r\n"
    ask(fw, "1PA120")
    ask(fw, "1PA-95")
    assert errors(fw) == [106, 107]  # positive / negative software limit, axis 1
    assert ask(fw, "1TP;1MD?") == "0.00000\r\n1\r\n"
    ask(fw, "1SR60")
    assert ask(fw, "1SR?") == "60.00000\r\n"
    ask(fw, "1PA70")
    assert errors(fw) == [106]
    ask(fw, "1SR99")  # beyond the hardware limit (95)
    ask(fw, "2SL50;2SR40")  # SR below SL
    assert errors(fw) == [101, 201]


def test_minimum_separation_refuses_end_point_only():
    fw = make_stage()
    ask(fw, "MO")  # lamp at theta_i = 45, phi_i = 0 (home)
    ask(fw, "1PA43")  # 2 deg from the lamp: refused, nothing moves
    assert errors(fw) == [129]  # axis 1, DIGITAL I/O INTERLOCK DETECTED
    assert ask(fw, "1TP;1DP?") == "0.00000\r\n0.00000\r\n"
    ask(fw, "1PA-45;1WS")  # forward side: 90 deg away
    assert errors(fw) == []
    ask(fw, "1PA35;1WS;1PA55;1WS")  # the path crosses the lamp: allowed (only end points count)
    assert errors(fw) == []
    ask(fw, "2PA55")  # moving the lamp onto the camera is refused too (axis 2)
    assert errors(fw) == [229]
    ask(fw, "3PA180;3WS;2PA55;2WS")  # lamp on the other side: far away from the camera
    assert errors(fw) == []


def test_error_codes_of_malformed_commands():
    fw = make_stage()
    assert ask(fw, "1YY") == ""
    assert ask(fw, "7TP") == ""  # a failing query produces no reply
    assert ask(fw, "PA30") == ""
    assert ask(fw, "1PA") == ""
    assert ask(fw, "1PAabc") == ""
    assert ask(fw, "1VA25;1AC100;1VA-1") == ""
    assert ask(fw, "1MD") == ""  # MD needs '?'
    assert errors(fw) == [6, 9, 37, 38, 101, 110, 111, 101, 6]


def test_tb_reports_code_timestamp_message_fifo_and_buffer_is_ten_deep():
    fw = make_stage()
    fw.clock.advance(1.0)
    ask(fw, "9TP")
    fw.clock.advance(1.0)
    ask(fw, "1PA10")
    # Timestamps count 400 us servo ticks: 1 s -> 2500, 2 s -> 5000.
    assert ask(fw, "TB?") == "9, 2500, AXIS NUMBER OUT OF RANGE\r\n"
    assert ask(fw, "TB") == "113, 5000, MOTOR NOT ENABLED\r\n"
    for _ in range(12):
        ask(fw, "1YY")
    assert len(errors(fw)) == 10


def test_stop_decelerates():
    fw = make_stage()
    ask(fw, "MO;1PA60")
    fw.clock.advance(1.0)
    ask(fw, "1ST")  # at 1 s: v = 10 deg/s, decelerate at 20 deg/s^2 -> 2.5 deg more
    ask(fw, "1WS")
    assert float(ask(fw, "1TP")) == pytest.approx(7.5 + 2.5, abs=2e-3)
    assert ask(fw, "1MD?") == "1\r\n"


@pytest.mark.parametrize("command, end, arrival", [
    ("1PA10", 10.0, 1.5),    # at 1 s: 7.5 deg, 10 deg/s; 2.5 deg is just the stopping distance
    ("1PR-20", 40.0, 4.5),   # PR from the commanded target (60): 32.5 deg to go at 10 deg/s
    ("1PA0", 0.0, 3.0),      # behind it: stop at 10 deg (0.5 s), then 10 deg back (1.5 s)
])
def test_a_move_received_during_a_move_retargets_it(command, end, arrival):
    """PA and PR are accepted while the axis moves (ESP300 manual, PA and PR, p. 3-112:
    usage "MIP"); the axis goes on from where it is, at its speed, to the new target (a
    reversal stops it first: the manual's caution). VA 10 deg/s, AC = AG 20 deg/s^2."""
    fw = make_stage()
    ask(fw, "MO;1PA60")
    fw.clock.advance(1.0)
    ask(fw, command)
    assert errors(fw) == []
    start = fw.clock.now()
    ask(fw, "1WS")
    # 0.02 s: the axis lands within its repeatability (1e-3 deg) of the target; landing just
    # short of the first case's stopping point takes a small move back (about 0.01 s)
    assert fw.clock.now() - start == pytest.approx(arrival - 1.0, abs=0.02)
    assert float(ask(fw, "1TP")) == pytest.approx(end, abs=3e-3)
    assert ask(fw, "1DP?") == f"{end:.5f}\r\n"


def test_velocity_changed_during_a_move_is_followed_from_where_the_axis_is():
    """VA, AC and AG changed during a motion are followed (the ESP300 takes them during a
    move): VA 5 at 1 s (7.5 deg, 10 deg/s) slows the axis to 5 deg/s at AG, so it reaches
    60 deg at 11.5 s instead of 6.5 s."""
    fw = make_stage()
    ask(fw, "MO;1PA60")
    fw.clock.advance(1.0)
    ask(fw, "1VA5")
    ask(fw, "1WS")
    assert fw.clock.now() == pytest.approx(11.5, abs=2e-3)
    assert float(ask(fw, "1TP")) == pytest.approx(60.0, abs=3e-3)
    ask(fw, "1PA50;1AC40")  # a change of AC mid-move: the move still ends at its target
    ask(fw, "1WS")
    assert float(ask(fw, "1TP")) == pytest.approx(50.0, abs=3e-3) and errors(fw) == []


def test_a_home_search_refuses_a_move_until_it_ends():
    fw = make_stage()
    ask(fw, "MO;1PA60;1WS;1OR")
    ask(fw, "1PA10")  # a home search is not a move PA may retarget
    assert 27 in errors(fw)


def test_motor_off_during_move_stops_axis():
    fw = make_stage()
    ask(fw, "MO;1PA60")
    fw.clock.advance(1.0)
    ask(fw, "1MF")
    here = float(ask(fw, "1TP"))
    fw.clock.advance(10.0)
    assert ask(fw, "1MD?;1MO?") == "1\r\n0\r\n"
    assert float(ask(fw, "1TP")) == here


def test_velocity_and_acceleration_settings_change_move_time():
    fw = make_stage()
    ask(fw, "MO;1VA20;1AC40;1AG40")
    assert ask(fw, "1VA?;1AC?;1AG?") == "20.00000\r\n40.00000\r\n40.00000\r\n"
    t0 = fw.clock.now()
    ask(fw, "1PA40;1WS")
    assert fw.clock.now() - t0 == pytest.approx(40 / 20 + 20 / 40, abs=1e-3)


def test_ws_delay_waits_in_simulated_time():
    fw = make_stage()
    t0 = fw.clock.now()
    ask(fw, "1WS600000")
    assert fw.clock.now() - t0 == pytest.approx(600.0)
    ask(fw, "1WS-5")
    assert errors(fw) == [7]


def test_repeatability_scatter_and_reproducibility():
    def positions(seed):
        fw = make_stage(seed=seed)
        ask(fw, "MO")
        out = []
        for k in range(40):
            ask(fw, f"1PA{20 + 10 * (k % 2)};1WS")
            out.append(fw.true_positions()[0] - (20 + 10 * (k % 2)))
        return np.array(out)

    a, b = positions(1), positions(1)
    assert np.array_equal(a, b)  # same seed, same commands: identical
    # 40 draws of sigma = 0.002 deg: sample std within [0.0013, 0.0027] (chi-square 99.9 %).
    assert 0.0013 < a.std(ddof=1) < 0.0027


def test_pymeasure_style_commands():
    """Command strings a third-party ESP300 client (PyMeasure's ESP300 class) sends."""
    fw = make_stage()
    for command in ("1MO", "2MO", "3MO"):
        ask(fw, command)
    assert ask(fw, "1MO?") == "1\r\n"
    ask(fw, "1PA12.5")
    assert ask(fw, "1MD?") == "0\r\n"
    ask(fw, "1WS0")
    assert ask(fw, "1MD?") == "1\r\n"
    assert abs(float(ask(fw, "1TP")) - 12.5) < 0.01
    assert ask(fw, "1SL?") == "-90.00000\r\n"
    assert ask(fw, "TE?") == "0\r\n"


# -- parameter ranges (docs/protocol.md section 1, "Parameter ranges") -----------------------

@pytest.mark.parametrize(
    "line, codes",
    [
        ("1WS1e400", [7]),  # overflows to inf: beyond the longest WS delay (non-axis parameter)
        ("WS1e309", [7]),
        ("1WS2147483648", [7]),  # one above MAX_WS_DELAY_MS = 2**31 - 1
        ("1VA1e-308", [101]),  # denormal velocity: below one encoder count per second
        ("1VA0.000999", [101]),
        ("1VA0", [101]),
        ("1VA-0", [101]),
        ("1VA1e400", [110]),  # inf is above the maximum velocity
        ("1AC1e-308", [101]),
        ("1AC1e400", [111]),
        ("1PA1e400", [106]),  # inf is beyond the positive software limit
        ("1PA-1e400", [107]),
        ("1PR1e400", [106]),
        ("1SL-1e400", [101]),
        ("1SR1e400", [101]),
        ("1OR1e400", [101]),
        ("1SN1e400", [101]),
        ("1PAnan", [101]),  # not a number in the manual's syntax
        ("1PAinf", [101]),
        ("1PA" + "9" * 70, [106]),  # a huge integer is a finite float: beyond SR
    ],
)
def test_out_of_range_numbers_are_refused_with_the_manuals_codes(line, codes):
    fw = make_stage()
    ask(fw, "MO")
    t0 = fw.clock.now()
    assert ask(fw, line) == ""
    assert errors(fw) == codes
    # Nothing changed: settings at their defaults, the axis at home, the clock unmoved.
    defaults = ("10.00000", "20.00000", "-90.00000", "90.00000", "0.00000", "1")
    assert ask(fw, "1VA?;1AC?;1SL?;1SR?;1DP?;1MD?") == "".join(f"{v}\r\n" for v in defaults)
    assert fw.clock.now() == t0


def test_refused_velocity_leaves_the_next_move_finite():
    """The line of the reliability report: 1VA1e-308 used to make the move last forever."""
    fw = make_stage()
    ask(fw, "MO")
    t0 = fw.clock.now()
    ask(fw, "1VA1e-308;1PA30;1WS")
    assert errors(fw) == [101]
    # The move ran with the unchanged velocity (10 deg/s, 20 deg/s^2): 30/10 + 10/20 s; the
    # end point scatters by the repeatability (0.002 deg = 0.2 ms at 10 deg/s): 2 ms is 10 sigma.
    assert fw.clock.now() - t0 == pytest.approx(3.5, abs=2e-3)


def test_minimum_rates_are_accepted_and_bound_the_longest_move():
    fw = make_stage(min_sep=None)
    ask(fw, "MO;3SL-185;3SR185;3VA0.001;3AC0.001")  # the minima: one encoder count per s, per s^2
    assert errors(fw) == []
    assert ask(fw, "3VA?;3AC?") == "0.00100\r\n0.00100\r\n"
    ask(fw, "3PA-185;3WS;3PA185")  # the whole hardware travel of axis 3 at the slowest rates
    t0 = fw.clock.now()
    ask(fw, "3WS")
    elapsed = fw.clock.now() - t0
    # 370 deg at 0.001 deg/s, plus one ramp time v/a = 1 s (trapezoid: d >= v^2/a); the
    # repeatability scatter (0.002 deg) of both end points changes it by at most ~10 s.
    assert elapsed == pytest.approx(move_duration(370.0, 0.001, 0.001), abs=10.0)
    assert 3.6e5 < elapsed < 3.8e5 and np.isfinite(elapsed)
    assert errors(fw) == []


def test_ws_accepts_its_longest_delay():
    fw = make_stage()
    t0 = fw.clock.now()
    ask(fw, "1WS2147483647")  # MAX_WS_DELAY_MS: about 24.9 days
    assert errors(fw) == []
    assert fw.clock.now() - t0 == pytest.approx(2147483.647)
    assert re.fullmatch(r"0, \d+, NO ERROR DETECTED\r\n", ask(fw, "TB?"))  # timestamps still work


@pytest.mark.parametrize(
    "line, codes",
    [
        ("1PA3\u0660", [101]),  # ARABIC-INDIC DIGIT ZERO is no digit of the ESP300 syntax
        ("\u0661PA30", [6]),  # ... nor an axis number
        ("1PA\u00a030", [101]),  # a no-break space is not a blank
        ("1PA30\udce9", [101]),  # a received byte 0xE9 (decoded with surrogateescape)
        ("1P\udce9A30", [6]),
    ],
)
def test_non_ascii_characters_are_not_digits_or_blanks(line, codes):
    fw = make_stage()
    ask(fw, "MO")
    assert ask(fw, line) == ""
    assert errors(fw) == codes
    assert ask(fw, "1DP?") == "0.00000\r\n"


def test_tab_is_a_blank():
    fw = make_stage()
    ask(fw, "MO;1\tPA\t10;1WS")
    assert errors(fw) == [] and ask(fw, "1DP?") == "10.00000\r\n"


@pytest.mark.parametrize("function, args", [
    ("move_duration", (30.0, 0.0, 20.0)),
    ("move_duration", (30.0, 10.0, float("inf"))),
    ("move_duration", (float("nan"), 10.0, 20.0)),
    ("move_duration", (30.0, 1e-320, 20.0)),  # positive but denormal: the duration overflows
    ("stop_profile", (0.0, 0.0, 10.0, 1e-320)),
    ("trapezoid_profile", (0.0, 0.0, 30.0, 1e-320, 20.0)),
    ("trapezoid_profile", (float("inf"), 0.0, 30.0, 10.0, 20.0)),
    ("stop_profile", (0.0, 0.0, 10.0, 0.0)),
])
def test_motion_profiles_refuse_non_finite_inputs(function, args):
    import drivers.emulator.stage_firmware as stage_firmware
    with pytest.raises(ValueError, match="must be finite"):
        getattr(stage_firmware, function)(*args)


# -- hardware-limit stop ----------------------------------------------------------------------

def test_dp_reports_the_stop_position_after_a_hardware_limit_stop():
    fw = make_stage()
    ask(fw, "MO")
    fw.limit_faults.add(1)  # the next move of axis 1 trips a limit switch half way
    ask(fw, "1PA-80")
    fw.clock.advance(1.0)
    # Mid-move the desired position is the commanded target (the switch has not tripped yet).
    assert ask(fw, "1DP?;1MD?") == "-80.00000\r\n0\r\n"
    ask(fw, "1WS")
    assert errors(fw) == [105]  # NEGATIVE HARDWARE LIMIT DETECTED, axis 1
    tp, dp, pa = (float(r) for r in ask(fw, "1TP;1DP?;1PA?").split())
    assert dp == pytest.approx(-40.0, abs=1e-9) and pa == dp  # tripped half way (-40 deg)
    # TP and DP agree within the repeatability (0.002 deg, 1 sigma; here both are the encoder
    # reading of the same rest position, so they agree to the resolution).
    assert abs(tp - dp) <= 0.002
    ask(fw, "1PR10;1WS")  # PR moves relative to the stop position, not to the old target
    assert ask(fw, "1DP?") == "-30.00000\r\n"
    assert abs(float(ask(fw, "1TP")) + 30.0) < 0.01  # 5 sigma of the repeatability
    assert errors(fw) == []


def test_limit_stop_error_is_queued_once_with_the_stop_time():
    fw = make_stage()
    ask(fw, "MO")
    fw.limit_faults.add(2)
    t0 = fw.clock.now()
    ask(fw, "2PA85")  # from 45: trips at 65 deg, 20 deg at 15 deg/s, 30 deg/s^2
    ask(fw, "2WS;2DP?")
    stop_ticks = int((t0 + move_duration(20.0, 15.0, 30.0)) / 400e-6)
    code, ticks, message = ask(fw, "TB?").strip().split(", ")
    assert (int(code), message) == (204, "POSITIVE HARDWARE LIMIT DETECTED")
    assert abs(int(ticks) - stop_ticks) <= 1  # rounding of the time to 400 us servo ticks
    assert ask(fw, "2DP?") == "65.00000\r\n" and errors(fw) == []


# -- encoder resolution (SU) ------------------------------------------------------------------

def test_su_reports_the_encoder_resolution_and_accepts_only_it():
    fw = make_stage()
    assert ask(fw, "1SU?;2SU?;3SU?") == "0.00100\r\n0.00100\r\n0.00100\r\n"
    assert ask(fw, "1SU0.001;1SU?") == "0.00100\r\n"  # its own resolution: accepted, no change
    assert errors(fw) == []
    ask(fw, "1SU0.01")  # the emulated encoders are fixed: any other value is x01
    ask(fw, "SU?")
    ask(fw, "4SU?")
    ask(fw, "1SU")
    assert errors(fw) == [101, 37, 9, 38]
    assert ask(fw, "1SU?") == "0.00100\r\n"


@settings(max_examples=300, deadline=None)
@given(start=st.floats(-180, 180), speed=st.floats(-20, 20), end=st.floats(-180, 180),
       velocity=st.floats(0.01, 20), acceleration=st.floats(0.01, 80), deceleration=st.floats(0.01, 80))
def test_a_move_from_any_state_is_continuous_bounded_and_ends_at_rest_on_target(start, speed, end, velocity,
                                                                               acceleration, deceleration):
    """profile_from_state (a PA/PR or VA/AC/AG during a move): position and velocity go on
    from the state it starts in, no acceleration exceeds AC or AG, the speed never exceeds
    the larger of the initial speed and VA, and the axis comes to rest exactly at the target."""
    profile = profile_from_state(5.0, start, speed, end, velocity, acceleration, deceleration)
    assert profile.position(5.0) == pytest.approx(start, abs=1e-9)
    assert profile.velocity(5.0) == pytest.approx(speed, abs=1e-9) or profile.end_time == 5.0
    assert profile.position(profile.end_time) == pytest.approx(end, abs=1e-6)
    assert profile.velocity(profile.end_time) == 0.0
    for t0, p0, v0, a, d in profile.segments:
        assert d >= 0 and abs(a) <= max(acceleration, deceleration) * (1 + 1e-12)
        assert max(abs(v0), abs(v0 + a * d)) <= max(abs(speed), velocity) * (1 + 1e-9) + 1e-12
    joints = [(seg[0] + seg[4], seg[1] + seg[2] * seg[4] + 0.5 * seg[3] * seg[4] ** 2, seg[2] + seg[3] * seg[4])
              for seg in profile.segments[:-1]]
    for (t, p, v), following in zip(joints, profile.segments[1:]):  # no jump between segments
        assert following[0] == pytest.approx(t) and following[1] == pytest.approx(p, abs=1e-6)
        assert following[2] == pytest.approx(v, abs=1e-6)


def test_a_home_search_ends_on_the_switch_to_one_count_whatever_the_seed():
    """OR stops on the home switch's index pulse, repeatable to one encoder count (0.001
    deg); a PA ends within the axis's repeatability instead. Before, after OR the position
    read -0.007 to +0.003 deg."""
    readings = set()
    for seed in range(20):
        fw = make_stage(seed=seed)
        ask(fw, "MO;1PA30;1WS;1OR;1WS")
        readings.add(ask(fw, "1TP"))
    assert readings == {"0.00000\r\n"}


def test_status_activity_and_velocity_queries_follow_the_axes():
    """TS (manual p. 3-142), TX (p. 3-144), TV and DV (p. 3-143): the status character has
    bit 6 set, as the manual's examples ('[P', 'P'); bits 0-2 the moving axes, bit 4 motor
    power; TX bit 4 a trajectory executing; TV/DV the velocity now."""
    fw = make_stage()
    assert ask(fw, "TS;TX") == "@\r\n@\r\n"  # nothing moves, motors off
    ask(fw, "MO;1PA60")
    fw.clock.advance(1.0)  # axis 1 cruising at VA = 10 deg/s
    assert ask(fw, "TS?;TX?") == "Q\r\nP\r\n"  # 0x40 | bit 0 | bit 4; 0x40 | bit 4
    assert ask(fw, "1TV;1DV;2TV") == "10.00000\r\n10.00000\r\n0.00000\r\n"
    ask(fw, "1WS")
    assert ask(fw, "TS") == "P\r\n" and ask(fw, "1TV") == "0.00000\r\n"
    ask(fw, "1TS")
    assert errors(fw) == [6]  # TS takes no axis

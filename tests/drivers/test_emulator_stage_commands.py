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
    assert errors(fw) == []


def test_wait_for_the_commanded_target_ends_with_the_move():
    """``PA`` then ``WP`` to the same position (InstrumentKit's ``move(wait=True)``): the
    trajectory ends at the commanded target, wherever within the repeatability it lands."""
    for seed in range(5):
        fw = make_stage(seed)
        ask(fw, "1MO;1PA30;1WP30")
        assert fw.waiting_for is None
        assert fw.clock.now() == pytest.approx(3.5, abs=0.02)  # passing 30 when it overshoots, else at rest
        assert float(ask(fw, "1TP")) == pytest.approx(30.0, abs=0.01)


def test_wait_for_a_position_never_passed_holds_the_controller_until_it_is_reset():
    """The hardware waits for ever: nothing more is executed or answered (the client sees
    its read timeout) until the controller is switched off and on."""
    fw = make_stage()
    ask(fw, "1MO;1PA30;1WS")
    assert ask(fw, "1WP60;1TP") == ""  # the query after the WP waits with it
    assert fw.waiting_for == (1, 60.0)
    assert ask(fw, "1TP") == "" and ask(fw, "TE?") == ""
    fw.clock.advance(3600.0)
    assert ask(fw, "1MD?") == ""
    fw.power_cycle()
    assert fw.waiting_for is None
    assert ask(fw, "1MO?;TE?") == "0\r\n0\r\n"
    assert float(ask(fw, "1TP")) == pytest.approx(30.0, abs=0.01)  # where the axis stood


def test_wait_for_a_position_behind_a_moving_axis_holds_the_controller():
    fw = make_stage()
    ask(fw, "1MO;1PA30")
    fw.clock.advance(2.0)  # past 15
    assert ask(fw, "1WP10;1TP") == "" and fw.waiting_for == (1, 10.0)


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


# -- home search modes (manual command OR, OM, SH, OL) ------------------------------------
@pytest.mark.parametrize("mode, mechanical, exact", [
    (0, None, True),     # the controller's +0 count (after DH: where the axis stood, about 12 deg)
    (1, 0.0, True),      # home switch and index
    (2, 0.0, False),     # home switch only
    (3, 95.0, False),    # positive hardware limit
    (4, -95.0, False),   # negative hardware limit
    (5, 95.0, True),     # positive limit and index
    (6, -95.0, True),    # negative limit and index
])
def test_each_home_search_mode_ends_on_its_switch_and_gives_it_the_home_preset(mode, mechanical, exact):
    for seed in range(3):
        fw = make_stage(seed)
        ask(fw, "1MO;1PA12;1WS;1DH0")  # 12 deg mechanical is now 0 (and the preset 0)
        ask(fw, "1SH5")
        zero_count = -fw.axes[1].offset  # the mechanical angle the controller reads 0 at
        assert zero_count == pytest.approx(12.0, abs=0.01)
        ask(fw, f"1OR{mode};1WS")
        true = fw.true_positions()[0]
        assert errors(fw) == []  # a limit switch ends the search: no x04/x05
        mechanical = zero_count if mode == 0 else mechanical
        if exact:
            assert true == pytest.approx(mechanical, abs=1e-9)
            assert ask(fw, "1TP") == "5.00000\r\n"
        else:  # on a switch's edge: within the axis's repeatability (0.002 deg)
            assert true == pytest.approx(mechanical, abs=0.01)
            assert float(ask(fw, "1TP")) == pytest.approx(5.0, abs=0.01)
        assert ask(fw, "1DP?") == "5.00000\r\n"


def test_a_bare_home_search_uses_the_mode_set_with_om():
    fw = make_stage()
    assert ask(fw, "1OM?") == "1\r\n"  # power-on: home switch and index
    ask(fw, "1MO;1OM4;1OR;1WS")
    assert ask(fw, "1OM?") == "4\r\n"
    assert fw.true_positions()[0] == pytest.approx(-95.0, abs=0.01)
    ask(fw, "1OM7;1OR9;1OMx")
    assert errors(fw) == [101, 101, 101]
    assert ask(fw, "1OM?") == "4\r\n"


def test_home_preset_and_low_homing_velocity_are_stored():
    fw = make_stage()
    assert ask(fw, "1SH?;1OL?") == "0.00000\r\n1.00000\r\n"
    ask(fw, "1SH-2.5;1OL0.5")
    assert ask(fw, "1SH?;1OL?;1DH?") == "-2.50000\r\n0.50000\r\n-2.50000\r\n"
    ask(fw, "1OL30")  # above VU (20): MAXIMUM VELOCITY EXCEEDED
    assert errors(fw) == [110]
    ask(fw, "1MO;1PA3;1WS;1DH1")  # DH sets the preset too
    assert ask(fw, "1SH?") == "1.00000\r\n"


def test_a_limit_switch_search_refused_by_the_interlock_changes_nothing():
    """Lamp polar axis to its positive limit (93 deg) with the camera at 90 deg: within the
    5-deg separation, refused with x29; coordinates kept."""
    fw = Esp300Firmware(SimClock(), np.random.default_rng(0),
                        interlock=lambda ends: abs(ends[0] - ends[1]) >= 5.0)
    ask(fw, "MO;1PA90;1WS;2PA60;2WS")
    ask(fw, "2OR3")
    assert errors(fw) == [229]
    assert float(ask(fw, "2TP")) == pytest.approx(60.0, abs=0.01)


def test_hardware_status_reads_the_limit_and_home_switches():  # manual p. 3-111
    fw = make_stage()
    # power-on: axes at home (axis 2's home 45 deg is on its switch's positive side, so are 1 and 3 at 0)
    assert ask(fw, "PH") == "18000000H, 7H\r\n"
    ask(fw, "1MO;1MT-;1WS")  # axis 1 onto its negative limit switch
    assert ask(fw, "PH?") == "18000100H, 6H\r\n"
    ask(fw, "1MT+;1WS")
    assert ask(fw, "01PH") == "18000001H, 7H\r\n"
    ask(fw, "PH1")
    assert errors(fw) == [6]


def test_free_program_memory_shrinks_as_programs_are_stored():
    fw = make_stage()
    assert ask(fw, "XM") == "61440\r\n"
    ask(fw, "1EP;1PA10;1WS;QP")
    assert ask(fw, "XM?") == f"{61440 - len('1PA10;') - len('1WS;')}\r\n"
    ask(fw, "1XX")
    assert ask(fw, "XM") == "61440\r\n"


def test_software_limit_configuration_is_stored_in_hexadecimal():
    fw = make_stage()
    assert ask(fw, "1ZS?") == "0H\r\n"
    ask(fw, "1ZS4H")
    assert ask(fw, "1ZS?") == "4H\r\n"


# -- trajectory modes (TJ, JK) ------------------------------------------------------------
def test_an_s_curve_move_limits_the_jerk_and_takes_a_over_jerk_longer():
    """``TJ2``: the trapezoid's corners rounded by the jerk ``JK``: acceleration continuous,
    its rate of change within ``JK``, the move longer by ``AC / JK`` than the trapezoid."""
    from drivers.emulator.stage_firmware import scurve_profile

    fw = make_stage()
    ask(fw, "1MO;1TJ2;1JK200;1PA30")
    assert ask(fw, "1TJ?;1JK?") == "2\r\n200.00000\r\n"
    profile = fw.axes[1].profile
    duration = profile.end_time - profile.start_time
    assert duration == pytest.approx(move_duration(30.0, 10.0, 20.0) + 20.0 / 200.0, abs=1e-3)  # + repeatability / VA
    times = np.linspace(profile.start_time, profile.end_time, 3601)
    velocity = np.array([profile.velocity(t) for t in times])
    acceleration = np.gradient(velocity, times)
    assert acceleration.max() == pytest.approx(20.0, rel=1e-3)
    assert np.abs(np.diff(acceleration) / np.diff(times)).max() <= 200.0 * 1.01  # jerk-limited
    ask(fw, "1WS")
    assert float(ask(fw, "1TP")) == pytest.approx(30.0, abs=0.01) and errors(fw) == []
    short = scurve_profile(0.0, 0.0, 0.5, 10.0, 20.0, 20.0, 200.0)  # peaks below VA and AC
    assert short.position(short.end_time) == pytest.approx(0.5, abs=1e-12)
    assert max(short.velocity(t) for t in np.linspace(0, short.end_time, 501)) < 10.0


def test_a_large_jerk_gives_the_trapezoid_back():
    from drivers.emulator.stage_firmware import scurve_profile, trapezoid_profile

    s_curve = scurve_profile(0.0, 0.0, 30.0, 10.0, 20.0, 10.0, 1e9)
    trapezoid = trapezoid_profile(0.0, 0.0, 30.0, 10.0, 20.0, 10.0)
    assert s_curve.end_time == pytest.approx(trapezoid.end_time, abs=1e-6)
    for t in np.linspace(0, trapezoid.end_time, 50):
        assert s_curve.position(t) == pytest.approx(trapezoid.position(t), abs=1e-6)


def test_the_trajectory_mode_rules():
    """Retargeting an S-curve move and changing TJ during a move: 27; jog and slave modes
    (3-6) refuse host moves (x32) and home searches (x27)."""
    fw = make_stage()
    ask(fw, "1MO;1TJ2;1PA30")
    ask(fw, "1PA10;1TJ1")
    assert errors(fw) == [27, 27]
    ask(fw, "1WS;1TJ4;1PA0;1PR1;1MT+;1OR1")
    assert errors(fw) == [132, 132, 132, 127]
    ask(fw, "1TJ1;1PA0;1WS")
    assert errors(fw) == [] and float(ask(fw, "1TP")) == pytest.approx(0.0, abs=0.01)

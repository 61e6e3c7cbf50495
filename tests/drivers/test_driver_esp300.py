"""ESP300 driver against the emulated controller: exact command/response pairs, errors.

Reference: docs/protocol.md section 1 (Newport ESP300 user's manual syntax and error
codes, Appendix A). Run over the in-process pyserial URL; test_driver_pty.py repeats the
round trips over a real pseudo-terminal.
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.rig import EmulatedRig
from drivers.errors import ResponseTimeout, StageError
from drivers.esp300 import ESP300, parse_error_entry

TIMEOUT = 0.3  # s; in-process replies take < 1 ms, so this only bounds failures


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.5 / np.pi)


@pytest.fixture
def emu():
    with EmulatedRig(lambert, seed=3, name="esp300-test") as rig:
        rig.start(pty=False)
        yield rig


@pytest.fixture
def stage(emu):
    with ESP300.open(emu.url("stage"), timeout=TIMEOUT) as s:
        yield s


def raw(stage, command, replies=1):
    """Send one exact line and return the exact reply lines (without CR LF)."""
    stage.line.write(command)
    return [stage.line.read_line() for _ in range(replies)]


def test_identity_and_power_on_state(stage):
    # Protocol: VE? -> "ESP300 Version 3.08 09/09/02"; motors off at power-on, units 7.
    assert raw(stage, "VE?") == ["ESP300 Version 3.08 09/09/02"]
    assert raw(stage, "1MO?") == ["0"]
    assert raw(stage, "2SN?") == ["7"]
    assert stage.units(2) == "degree"
    assert raw(stage, "TB?")[0].endswith(", NO ERROR DETECTED")
    assert raw(stage, "TE?") == ["0"]


def test_exact_query_replies(stage):
    # Fixed-point replies with 5 decimals; limits and defaults of the protocol tables.
    assert raw(stage, "1SL?;1SR?", 2) == ["-90.00000", "90.00000"]
    assert raw(stage, "2SL?;2SR?", 2) == ["0.00000", "90.00000"]
    assert raw(stage, "01VA?") == ["10.00000"]  # leading zero accepted
    assert raw(stage, "3AC?") == ["40.00000"]
    assert raw(stage, "2DP?") == ["45.00000"]  # home of axis 2
    assert stage.travel_limits(3) == (-180.0, 180.0)
    assert stage.velocity(2) == 15.0 and stage.acceleration(1) == 20.0


def test_move_round_trip_and_readback(stage, emu):
    stage.motor_on(1)
    assert stage.motor_is_on(1)
    stage.move_absolute(1, 30.0)
    # Sent bytes are exactly the manual's syntax, CR-terminated.
    assert (">", b"1PA30.000000\r") in [(d, b) for _, d, b in stage.line.transcript]
    assert stage.motion_done(1)
    # Repeatability 0.002 deg (1 sigma), encoder 0.001 deg: 0.01 deg is 5 sigma.
    assert stage.position(1) == pytest.approx(30.0, abs=0.01)
    assert stage.desired_position(1) == 30.0
    assert emu.control.true_state().positions_deg[0] == pytest.approx(30.0, abs=0.01)
    stage.move_relative(1, -10.0)
    assert stage.position(1) == pytest.approx(20.0, abs=0.01)
    assert stage.positions() == pytest.approx({1: 20.0, 2: 45.0, 3: 0.0}, abs=0.01)


def test_wait_advances_simulated_time(stage, emu):
    before = emu.control.now()
    stage.wait(600.0)
    # WS600000 waits 600 s of simulated time (plus line transfer times of ~ms).
    assert emu.control.now() - before == pytest.approx(600.0, abs=0.1)


@pytest.mark.parametrize(
    "command, code, message",
    [
        ("1PA120", 106, "POSITIVE SOFTWARE LIMIT DETECTED"),
        ("2PA-5", 207, "NEGATIVE SOFTWARE LIMIT DETECTED"),
        ("1PA45", 129, "DIGITAL I/O INTERLOCK DETECTED"),  # camera onto the lamp (home 45, 0)
        ("7PA10", 9, "AXIS NUMBER OUT OF RANGE"),
        ("1YY5", 6, "COMMAND DOES NOT EXIST"),
        ("PA30", 37, "AXIS NUMBER MISSING"),
        ("1PA", 38, "COMMAND PARAMETER MISSING"),
        ("1VA500", 110, "MAXIMUM VELOCITY EXCEEDED"),
    ],
)
def test_refused_commands_raise_with_code_and_message_and_nothing_moves(stage, emu, command, code, message):
    for axis in (1, 2, 3):
        stage.motor_on(axis)
    before = emu.control.true_state().positions_deg
    with pytest.raises(StageError) as info:
        stage.send(command)
    error = info.value
    assert (error.code, error.message, error.command) == (code, message, command)
    assert str(code) in str(error) and message in str(error)
    if code >= 100:
        assert error.axis == code // 100
    emu.control.advance(10.0)
    assert emu.control.true_state().positions_deg == before


def test_motor_off_move_is_refused(stage, emu):
    with pytest.raises(StageError) as info:
        stage.move_absolute(2, 30.0)
    assert info.value.code == 213 and info.value.message == "MOTOR NOT ENABLED"
    assert stage.position(2) == pytest.approx(45.0, abs=0.01)


def test_failed_query_reports_the_controller_error_not_a_timeout(stage):
    # "7TP" gets no reply (protocol example); the driver reads TB? and raises error 9.
    with pytest.raises(StageError) as info:
        stage.ask("7TP", float)
    assert info.value.code == 9


def test_unknown_query_without_reply_and_line_stays_in_step(stage):
    with pytest.raises(StageError) as info:
        stage.ask("1QQ?")
    assert info.value.code == 6
    assert stage.identity().startswith("ESP300")  # the next exchange is in step


def test_error_buffer_drains_oldest_first(stage):
    for axis in (1, 2, 3):
        stage.motor_on(axis)
    stage.send("1PA120;2PA-5;9TP", check=False)
    codes = [e.code for e in stage.errors()]
    assert codes == [106, 207, 9]
    assert stage.errors() == []


def test_parse_error_entry_rejects_garbage():
    with pytest.raises(Exception, match="TB\\?"):
        parse_error_entry("garbage")


def test_disconnected_controller_times_out_quickly(stage, emu):
    emu.control.disconnect("stage")
    with pytest.raises(ResponseTimeout):
        stage.identity()
    emu.control.reconnect("stage")
    assert stage.identity().startswith("ESP300")


def test_encoder_resolution_exact_pair(stage):
    # Protocol: xxSU? -> the encoder resolution with 5 decimals; the emulator's axes: 0.001 deg.
    assert raw(stage, "1SU?") == ["0.00100"]
    assert [stage.encoder_resolution(axis) for axis in (1, 2, 3)] == [0.001, 0.001, 0.001]
    assert (">", b"3SU?\r") in [(d, b) for _, d, b in stage.line.transcript]
    with pytest.raises(ValueError, match="axis"):
        stage.encoder_resolution(4)


def test_encoder_resolution_refuses_a_nonsense_reply(stage, monkeypatch):
    from drivers.errors import ProtocolError

    for reply in (0.0, -0.001, float("inf"), float("nan")):
        monkeypatch.setattr(stage, "ask", lambda command, parse=str, **kw: reply)
        with pytest.raises(ProtocolError, match="encoder resolution"):
            stage.encoder_resolution(1)


def test_dp_after_a_hardware_limit_stop_is_where_the_axis_stopped(stage, emu):
    stage.motor_on(1)
    emu.control.hit_limit(1)
    with pytest.raises(StageError) as info:
        stage.move_absolute(1, -60.0)
    assert info.value.code == 105
    # The axis tripped the switch half way (-30 deg): DP? follows it, TP agrees within the
    # repeatability (0.002 deg, 1 sigma; both are encoder readings of the rest position).
    assert stage.desired_position(1) == pytest.approx(-30.0, abs=1e-9)
    assert abs(stage.position(1) - stage.desired_position(1)) <= 0.002

"""The rig's clock modes (drivers/emulator/clock.py, docs/emulator.md "Time"): a wall clock
that sleeping and polling clients see advance, jumps while a client waits on the rig,
pause / speed / step from the side channel; the event mode unchanged."""
from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.emulator.clock import SimClock
from drivers.emulator.rig import EmulatedRig
from drivers.emulator.transports import transfer_time


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


def test_the_wall_clock_follows_wall_time_times_the_speed():
    clock = SimClock("wall", speed=20.0)
    start = time.monotonic()
    t0 = clock.now()
    time.sleep(0.1)
    t1 = clock.now()
    elapsed = time.monotonic() - start
    assert 20.0 * 0.1 <= t1 - t0 <= 20.0 * elapsed


def test_the_event_clock_does_not_follow_wall_time():
    clock = SimClock("event")
    time.sleep(0.02)
    assert clock.now() == 0.0


def test_a_wait_jumps_the_wall_clock_at_once_and_it_runs_on_from_there():
    clock = SimClock("wall", speed=1.0)
    start = time.monotonic()
    clock.wait_until(1000.0)
    assert time.monotonic() - start < 0.5  # a jump, not a 1000-s sleep
    assert 1000.0 <= clock.now() < 1001.0
    clock.advance(10.0)
    assert 1010.0 <= clock.now() < 1011.0


def test_a_wait_for_a_time_already_past_leaves_the_clock_alone():
    clock = SimClock("wall", speed=1000.0)
    time.sleep(0.01)
    before = clock.now()
    clock.wait_until(0.5)
    assert clock.now() >= before >= 10.0


def test_pause_stops_the_wall_part_and_steps_still_move_it():
    clock = SimClock("wall", speed=1000.0)
    clock.pause()
    held = clock.now()
    time.sleep(0.02)
    assert clock.now() == held and clock.paused
    clock.advance(2.0)
    assert clock.now() == held + 2.0
    clock.resume()
    time.sleep(0.01)
    assert clock.now() >= held + 2.0 + 1000 * 0.01


def test_set_speed_changes_the_rate_from_now_on_and_time_never_goes_back():
    clock = SimClock("wall", speed=1000.0)
    time.sleep(0.01)
    before = clock.now()
    clock.set_speed(1.0)
    after = clock.now()
    time.sleep(0.02)
    assert before <= after <= clock.now() < after + 1.0


def test_the_real_time_clock_sleeps_at_its_speed():
    clock = SimClock("realtime", speed=10.0)
    start = time.monotonic()
    clock.advance(1.0)  # 0.1 s of wall time at 10x
    assert 0.1 <= time.monotonic() - start < 0.9


@pytest.mark.parametrize("kwargs, message", [
    ({"mode": "fast"}, "clock mode must be one of"),
    ({"mode": "wall", "speed": 0.0}, "speed must be a finite number > 0"),
    ({"mode": "wall", "speed": float("inf")}, "speed must be a finite number > 0"),
    ({"mode": "wall", "speed": -2.0}, "speed must be a finite number > 0"),
])
def test_bad_clock_settings_are_refused_naming_what_is_expected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SimClock(**kwargs)


def test_a_real_time_clock_refuses_to_pause():
    with pytest.raises(ValueError, match="cannot pause"):
        SimClock("realtime").pause()


def _line(rig, device, text):
    return rig.channels[device].process(text)


def test_a_warm_up_done_with_sleep_warms_the_lamp_on_the_wall_clock():
    """``OUTP ON``, sleep, ``MEAS:CURR?``: the event clock still reads the switch-on surge
    (the client's sleep did not count); the wall clock has let the filament heat."""
    readings = {}
    for mode in ("event", "wall"):
        rig = EmulatedRig(lambert, seed=3, clock_mode=mode, speed=20.0)
        _line(rig, "lamp", "VOLT 100")
        _line(rig, "lamp", "OUTP ON")
        time.sleep(0.25)  # 5 s of simulated time at 20x
        readings[mode] = float(_line(rig, "lamp", "MEAS:CURR?"))
        hot = rig.lamp.current(rig.clock.now() + 3600.0)
        readings[mode] /= hot
    assert readings["event"] > 2.0  # still in the cold filament's inrush
    assert readings["wall"] == pytest.approx(1.0, abs=0.01)


def test_a_polled_move_ends_in_hardware_time_divided_by_the_speed():
    """A client polling ``MD?`` every 20 ms sees a move end after the profile's duration in
    simulated time, i.e. about duration / speed of wall time (the event clock needed one
    poll per transfer time: 1.5 s of motion took 20.5 s of wall time at 50-ms polls)."""
    speed = 10.0
    rig = EmulatedRig(lambert, seed=3, clock_mode="wall", speed=speed, motors_on=True)
    _line(rig, "stage", "1VA10")
    t0, start = rig.clock.now(), time.monotonic()
    _line(rig, "stage", "1PA10")
    duration = rig.stage.axes[1].profile.end_time - t0
    polls = 0
    while _line(rig, "stage", "1MD?") != b"1\r\n":
        polls += 1
        time.sleep(0.02)
        assert polls < 500, "the move never ended"
    wall = time.monotonic() - start
    charged = (polls + 2) * transfer_time(len("1MD?") + 1 + 3, 19200)
    assert rig.clock.now() - t0 >= duration
    assert wall >= (duration - charged) / speed * 0.95
    assert wall < 10 * duration / speed  # the event clock: 1.5 s / 0.4 ms per poll x 20 ms


def test_a_client_waiting_on_the_rig_jumps_the_wall_clock():
    """``WS`` (wait for stop) blocks the client on the rig: the clock jumps to the move's end
    instead of waiting the motion out on the wall clock."""
    rig = EmulatedRig(lambert, seed=3, clock_mode="wall", speed=1.0, motors_on=True)
    _line(rig, "stage", "1VA1")
    start = time.monotonic()
    _line(rig, "stage", "1PA30;1WS;1TP?")
    assert time.monotonic() - start < 5.0  # a 30-s move, jumped
    assert float(_line(rig, "stage", "1TP?")) == pytest.approx(30.0, abs=0.01)
    assert rig.clock.now() >= 30.0


def test_the_side_channel_pauses_speeds_up_and_reports_the_clock():
    rig = EmulatedRig(lambert, seed=3, clock_mode="wall", speed=1.0)
    rig.control.pause()
    held = rig.control.now()
    time.sleep(0.02)
    assert rig.control.clock() == {"mode": "wall", "speed": 1.0, "paused": True, "time_s": held}
    rig.control.set_speed(100.0)
    rig.control.resume()
    time.sleep(0.02)
    assert rig.control.now() >= held + 100 * 0.02
    with pytest.raises(ValueError, match="speed must be"):
        rig.control.set_speed(0)

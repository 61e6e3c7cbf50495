"""Camera and lamp drivers against the emulated instruments: exact pairs and errors.

Reference: docs/protocol.md sections 2 (camera) and 3 (lamp supply), IEEE 488.2 error
queue behaviour (a failing query returns nothing; the error is read with SYST:ERR?).
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.camera import Camera, Roi, RoiStats, SensorInfo
from drivers.emulator.rig import EmulatedRig
from drivers.errors import CameraError, LampError, ProtocolError, ResponseTimeout
from drivers.lamp import Lamp
from drivers.scpi import parse_scpi_error

TIMEOUT = 0.3  # s; in-process replies take < 1 ms, so this only bounds failures


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1.0 / np.pi)


@pytest.fixture(scope="module")
def emu():
    with EmulatedRig(lambert, seed=5, name="camlamp-test", lamp_warm=True) as rig:
        rig.start(pty=False)
        yield rig


@pytest.fixture
def camera(emu):
    with Camera.open(emu.url("camera"), timeout=TIMEOUT) as cam:
        cam.reset()
        cam.clear_status()
        yield cam


@pytest.fixture
def lamp(emu):
    with Lamp.open(emu.url("lamp"), timeout=TIMEOUT) as supply:
        supply.clear_status()
        yield supply


def raw(instrument, command):
    instrument.line.write(command)
    return instrument.line.read_line()


def test_camera_exact_pairs(camera):
    assert raw(camera, "*IDN?").startswith("GONIO,CCD-512,")
    assert raw(camera, "SENS:INFO?") == "512,480,12,15,150,1828.8"
    assert raw(camera, "*OPC?") == "1"
    assert raw(camera, "SYST:ERR?") == '0,"No error"'
    camera.line.write("EXP 0.025;GAIN 2")
    assert raw(camera, "EXP?;GAIN?") == "0.025;2"
    assert raw(camera, "SHUT?") == "OPEN"
    assert raw(camera, "ROI?") == "0,0,512,480"


def test_camera_driver_settings_round_trip(camera):
    info = camera.sensor_info()
    assert info == SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)
    assert info.max_dn == 4095
    camera.set_exposure(0.0125)
    assert camera.exposure() == 0.0125
    camera.set_gain(4)
    assert camera.gain() == 4.0
    camera.close_shutter()
    assert not camera.shutter_is_open()
    camera.open_shutter()
    assert camera.shutter_is_open()
    roi = Roi(206, 190, 100, 100)
    camera.set_roi(roi)
    assert camera.roi() == roi


def test_roi_stats_agree_with_the_full_frame(camera):
    camera.set_exposure(0.01)
    camera.set_roi(Roi(206, 190, 100, 100))
    camera.acquire()
    stats = camera.roi_stats()
    frame = camera.frame()
    assert frame.shape == (480, 512) and frame.dtype == np.uint16
    window = frame[190:290, 206:306].astype(float)
    # ROI:STAT? reports mean and std (ddof = 1) with 4 decimals of the same frame.
    assert stats.mean == pytest.approx(window.mean(), abs=1e-4)
    assert stats.std == pytest.approx(window.std(ddof=1), abs=1e-4)
    assert stats.pixels == 10000 and stats.saturated == 0


def test_dark_frame_with_closed_shutter(camera):
    camera.set_exposure(0.01)
    camera.set_roi(Roi(206, 190, 100, 100))
    camera.acquire()
    light = camera.roi_stats().mean
    camera.close_shutter()
    camera.acquire()
    dark = camera.roi_stats()
    # Dark level: offset 100 DN + 0.1 DN/e- * 20 e-/s * 0.01 s = 100.02 DN.
    assert dark.mean == pytest.approx(100.0, abs=0.5)
    assert light > dark.mean + 100


@pytest.mark.parametrize(
    "command, code",
    [("EXP 100", -222), ("GAIN 0.5", -222), ("ROI 500,0,100,10", -222), ("FOO 1", -113),
     ("EXP", -109), ("SHUT MAYBE", -104)],
)
def test_camera_errors_raise_with_device_code_and_message(camera, command, code):
    with pytest.raises(CameraError) as info:
        camera.write(command)
    assert info.value.code == code and info.value.command == command
    assert info.value.message  # the camera's own text
    assert camera.errors() == []  # the queue was drained


def test_camera_query_before_acquire_reports_settings_conflict(camera):
    # After *RST no frame exists: ROI:STAT? is not answered and -221 is queued.
    with pytest.raises(CameraError) as info:
        camera.roi_stats()
    assert info.value.code == -221


def test_unknown_query_is_an_error_not_a_hang(camera):
    with pytest.raises(CameraError) as info:
        camera.query("ACQ?")
    assert info.value.code == -113
    assert camera.identity().startswith("GONIO")


def test_camera_fault_during_acquire(camera, emu):
    emu.control.camera_fault(True)
    try:
        with pytest.raises(CameraError) as info:
            camera.acquire()
        assert info.value.code == -200
    finally:
        emu.control.camera_fault(False)


def test_garbled_reply_is_retried(camera, emu):
    emu.control.garble("camera", 1)
    # The first EXP? reply is corrupted (not a number): the driver reads SYST:ERR?
    # (empty), retries once and gets the right value.
    camera.set_exposure(0.02)
    assert camera.exposure() == 0.02


def test_stalled_camera_gives_timeout_not_hang(camera, emu):
    emu.control.stall("camera", 1.0)
    with pytest.raises(ResponseTimeout):
        camera.query("EXP?", retries=0)
    emu.control.clear_faults()


def test_lamp_exact_pairs_and_driver(lamp, emu):
    assert raw(lamp, "*IDN?").startswith("GONIO,LPS-300,")
    lamp.set_voltage(120)
    lamp.output_on()
    assert raw(lamp, "OUTP?;VOLT?") == "1;120"
    assert lamp.output_is_on() and lamp.voltage_setpoint() == 120.0
    # 0.05 % voltage noise; 2.5 A at 120 V.
    assert lamp.measured_voltage() == pytest.approx(120.0, rel=0.005)
    assert lamp.measured_current() == pytest.approx(2.5, rel=0.01)
    assert lamp.lamp_status() == "OK"
    with pytest.raises(LampError) as info:
        lamp.set_voltage(200)
    assert info.value.code == -222


def test_lamp_burn_out_is_reported(lamp, emu):
    lamp.output_on()
    emu.control.burn_out_lamp()
    try:
        assert lamp.lamp_status() == "FAULT"
        assert lamp.measured_current() == 0.0
        with pytest.raises(LampError, match="FAULT"):
            lamp.check_lamp()
    finally:
        emu.control.replace_lamp()


def test_reply_parsers_reject_malformed_replies():
    with pytest.raises(ProtocolError):
        parse_scpi_error("garbage")
    with pytest.raises(ValueError):
        RoiStats.parse("1,2,3")
    with pytest.raises(ValueError):
        SensorInfo.parse("512,480")

"""Round trips through the emulator over real pseudo-terminals (raw mode), as over a
USB-serial adapter: exact command/response pairs per device, a FRAME? block, and a Rig
measurement. docs/protocol.md, "Transports" (1).
"""
from __future__ import annotations

import os

import numpy as np
import pytest

from drivers.camera import Camera
from drivers.emulator.rig import EmulatedRig
from drivers.errors import CameraError, StageError
from drivers.esp300 import ESP300
from drivers.lamp import Lamp
from drivers.rig import Rig

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")

# A pty round trip takes ~0.1-1 ms; 2 s only bounds a failure (and FRAME?'s 491 kB).
TIMEOUT = 2.0


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


@pytest.fixture(scope="module")
def ports():
    with EmulatedRig(lambert, seed=51, name="pty-test", lamp_warm=True) as emu:
        addresses = emu.start(pty=True)
        yield {device: entry["pty"] for device, entry in addresses.items()}


def test_addresses_are_pseudo_terminals(ports):
    for path in ports.values():
        assert path.startswith("/dev/pts/") or "pty" in path or "tty" in path
        assert os.path.exists(path)


def test_stage_round_trip_over_pty(ports):
    with ESP300.open(ports["stage"], timeout=TIMEOUT) as stage:
        stage.line.write("VE?")
        assert stage.line.read_line() == "ESP300 Version 3.08 09/09/02"
        stage.motor_on(3)
        stage.line.write("3MO?;3SL?")
        assert [stage.line.read_line(), stage.line.read_line()] == ["1", "-180.00000"]
        stage.move_absolute(3, 25.0)
        assert stage.position(3) == pytest.approx(25.0, abs=0.01)
        with pytest.raises(StageError) as info:
            stage.send("3PA250")
        assert info.value.code == 306


def test_camera_round_trip_and_frame_block_over_pty(ports):
    with Camera.open(ports["camera"], timeout=TIMEOUT) as camera:
        camera.line.write("SENS:INFO?")
        assert camera.line.read_line() == "512,480,12,15,150,1828.8"
        camera.set_exposure(0.01)
        camera.acquire()
        frame = camera.frame()
        assert frame.shape == (480, 512) and frame.dtype == np.uint16
        assert 90 < frame[0, 0] < 115  # background: dark level ~100 DN
        with pytest.raises(CameraError) as info:
            camera.write("EXP 100")
        assert info.value.code == -222


def test_lamp_round_trip_over_pty(ports):
    with Lamp.open(ports["lamp"], timeout=TIMEOUT) as lamp:
        lamp.line.write("*IDN?")
        assert lamp.line.read_line().startswith("GONIO,LPS-300,")
        lamp.set_voltage(110.0)
        assert lamp.voltage_setpoint() == 110.0
        assert lamp.lamp_status() == "OK"


def test_rig_measures_over_pty(ports):
    with Rig.open(ports["stage"], ports["camera"], ports["lamp"], timeout=TIMEOUT) as rig:
        rig.lamp_on(120.0)
        a = rig.measure(30.0, 0.0, -40.0)
        b = rig.measure(30.0, 0.0, 50.0)
        # Lambertian: the same radiance at both camera angles (lamp noise ~0.1 %).
        assert a.radiance == pytest.approx(b.radiance, rel=0.005)

"""The simulated clock offered over the serial line (``SIM:TIME?``) and used by the Rig."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.camera import Camera
from drivers.emulator.rig import EmulatedRig
from drivers.rig import Rig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


def test_sim_time_query_reports_the_simulated_clock():
    rig = EmulatedRig(lambert, seed=5)
    rig.control.advance(12.5)
    assert rig.channels["camera"].process("SIM:TIME?") == b"12.500000\n"
    # The camera line took its transfer time: 9 + 11 bytes at 115200 baud, 10 bits each.
    expected = 12.5 + 20 * 10 / 115200
    assert rig.channels["lamp"].process("SIMulation:TIME?") == f"{expected:.6f}\n".encode()


def test_rig_uses_the_simulated_clock_of_an_external_emulator():
    with EmulatedRig(lambert, seed=5, name="clock", lamp_warm=True) as emu:
        addresses = emu.start(pty=True)
        with Rig.open(addresses["stage"]["pty"], addresses["camera"]["pty"], addresses["lamp"]["pty"]) as rig:
            assert rig.instrument_clock is not None
            before = rig.instrument_clock()
            rig.wait(100.0)  # 100 s of simulated time, at once in fast mode
            after = rig.instrument_clock()
            assert after - before == pytest.approx(100.0, abs=0.05)  # plus the lines' transfer times
            assert after == pytest.approx(emu.control.now(), abs=0.01)
            assert rig.camera.errors() == []


def test_a_camera_without_the_query_has_no_instrument_clock():
    """A real camera answers -113 to SIM:TIME?: the Rig falls back to wall-clock time."""
    with EmulatedRig(lambert, seed=5, name="no-clock") as emu:
        emu.start(pty=False)
        firmware = emu.camera
        firmware._commands = [c for c in firmware._commands if c.header != "SIMulation:TIME"]
        with Camera.open(emu.url("camera")) as camera:
            assert camera.simulated_time() is None
            assert camera.errors() == []  # the -113 was drained

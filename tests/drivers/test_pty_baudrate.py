"""A pty client at the wrong baud rate gets what a real line gives: garbage (docs/emulator.md)."""
from __future__ import annotations

import numpy as np
import pytest
import serial

from drivers.emulator.rig import EmulatedRig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


def exchange(path: str, baudrate: int, line: bytes) -> bytes:
    with serial.Serial(path, baudrate=baudrate, timeout=0.3) as port:
        port.write(line)
        return port.readline()


def test_right_rate_is_answered_wrong_rate_is_garbled():
    with EmulatedRig(lambert, seed=6, name="baud") as rig:
        addresses = rig.start(pty=True)
        camera = addresses["camera"]["pty"]
        assert exchange(camera, 115200, b"*IDN?\n") == b"GONIO,CCD-512,SN0001,1.0\n"
        assert exchange(camera, 9600, b"*IDN?\n") == b""  # the camera heard noise: no reply
        assert exchange(camera, 115200, b"SYST:ERR?\n").startswith(b"-100,")  # ... and queued an error
        assert exchange(addresses["stage"]["pty"], 19200, b"VE?\r") == b"ESP300 Version 3.08 09/09/02\r\n"


def test_the_check_can_be_switched_off():
    with EmulatedRig(lambert, seed=6, name="baud-off") as rig:
        addresses = rig.start(pty=True, check_baudrate=False)
        assert exchange(addresses["lamp"]["pty"], 115200, b"*IDN?\n") == b"GONIO,LPS-300,SN0001,1.0\n"


def test_a_client_that_sets_no_rate_meets_the_instruments_rate():
    """The terminal starts at the instrument's rate: a client that never sets one is answered."""
    import os
    import select

    with EmulatedRig(lambert, seed=6, name="baud-raw") as rig:
        addresses = rig.start(pty=True)
        fd = os.open(addresses["stage"]["pty"], os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, b"VE?\r")
            reply = b""
            while not reply.endswith(b"\r\n") and select.select([fd], [], [], 2.0)[0]:
                reply += os.read(fd, 100)
            assert reply == b"ESP300 Version 3.08 09/09/02\r\n"
        finally:
            os.close(fd)


@pytest.mark.parametrize("device, baudrate", [("stage", 19200), ("camera", 115200), ("lamp", 9600)])
def test_each_instrument_checks_its_own_rate(device, baudrate):
    with EmulatedRig(lambert, seed=6, name=f"baud-{device}") as rig:
        rig.start(pty=True)
        transport = dict(rig._transports[device])["pty"]
        with serial.Serial(transport.path, baudrate=baudrate) as port:
            assert not transport.rate_mismatch()
            port.baudrate = 38400
            assert transport.rate_mismatch()

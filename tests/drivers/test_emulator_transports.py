"""Emulated instruments over real transports: pseudo-terminal, TCP loopback, in-process URL,
and the fault-injection side channel (docs/protocol.md "Transports"; docs/emulator.md)."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest
import serial

from drivers.emulator.rig import EmulatedRig, find_rig
from drivers.emulator.transports import LineSplitter


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.9 / np.pi)


@pytest.fixture
def rig(tmp_path):
    with EmulatedRig(lambert, seed=11, name="transport-test", lamp_warm=True) as r:
        r.start(pty=True, tcp=True, symlinks={"stage": str(tmp_path / "gonio-stage")})
        yield r


def open_port(address: str, device: str, timeout: float = 2.0) -> serial.SerialBase:
    baud = {"stage": 19200, "camera": 115200, "lamp": 9600}[device]
    return serial.serial_for_url(address, baudrate=baud, timeout=timeout)


@pytest.mark.parametrize("kind", ["pty", "tcp", "url"])
def test_exact_pairs_over_each_transport(rig, kind):
    addresses = rig.addresses()
    with open_port(addresses["stage"][kind], "stage") as stage, \
            open_port(addresses["camera"][kind], "camera") as camera, \
            open_port(addresses["lamp"][kind], "lamp") as lamp:
        stage.write(b"VE?\r")
        assert stage.readline() == b"ESP300 Version 3.08 09/09/02\r\n"
        stage.write(b"1MO;1PA-30;1WS;1MD?\r\n")  # CR LF accepted
        assert stage.readline() == b"1\r\n"
        stage.write(b"1MO?\n")  # LF accepted
        assert stage.readline() == b"1\r\n"
        camera.write(b"*IDN?\n")
        assert camera.readline() == b"GONIO,CCD-512,SN0001,1.0\n"
        lamp.write(b"OUTP?;STAT:LAMP?\n")
        assert lamp.readline() == b"1;OK\n"
        camera.write(b"EXP 0.02;ROI 206,190,100,100;ACQ;ROI:STAT?\n")
        stat = camera.readline().decode().strip().split(",")
        camera.write(b"FRAME?\n")
        header = camera.read(8)
        payload = camera.read(491520)
        assert header == b"#6491520" and len(payload) == 491520 and camera.read(1) == b"\n"
        frame = np.frombuffer(payload, "<u2").reshape(480, 512)[190:290, 206:306]
        assert float(stat[0]) == pytest.approx(frame.mean(), abs=5e-5)


def test_symlink_points_at_the_pty_and_is_removed_on_close(tmp_path):
    link = tmp_path / "gonio-camera"
    with EmulatedRig(lambert, seed=1, name="link-test") as r:
        addresses = r.start(pty=True, symlinks={"camera": str(link)})
        assert addresses["camera"]["pty"] == str(link)
        assert os.path.realpath(link).startswith("/dev/pts/")
        with serial.Serial(str(link), 115200, timeout=2) as port:  # a plain port path
            port.write(b"*OPC?\n")
            assert port.readline() == b"1\n"
    assert not link.exists()


def test_url_handler_registry_and_errors(rig):
    assert find_rig("transport-test") is rig
    with pytest.raises(serial.SerialException, match="no emulated rig"):
        serial.serial_for_url("gonio-sim://stage?rig=nope", baudrate=19200)
    with pytest.raises(serial.SerialException, match="unknown device"):
        serial.serial_for_url("gonio-sim://motor?rig=transport-test", baudrate=19200)
    with serial.serial_for_url("goniosim://lamp?rig=transport-test", baudrate=9600, timeout=1) as alias:
        alias.write(b"*OPC?\n")
        assert alias.readline() == b"1\n"


def test_wrong_baud_rate_gets_no_reply(rig):
    with serial.serial_for_url(rig.url("stage"), baudrate=9600, timeout=0.2) as port:
        port.write(b"VE?\r")
        assert port.readline() == b""


def test_overlong_and_garbage_lines_do_not_desynchronise(rig):
    with open_port(rig.url("stage"), "stage") as stage:
        stage.write(b"1" * 5000 + b"\r" + b"\x00\xff;;\r" + b"TE?\r")
        assert stage.readline() == b"6\r\n"  # overlong line: COMMAND DOES NOT EXIST
        stage.write(b"TE?\r")
        assert stage.readline() == b"6\r\n"  # the garbage line
        stage.write(b"TE?\r")
        assert stage.readline() == b"0\r\n"


def test_line_splitter_terminators():
    s = LineSplitter(max_line=8)
    assert list(s.feed(b"a\rb\nc\r\n\r\n")) == ["a", "b", "c"]
    out = list(s.feed(b"0123456789\rok\r"))
    assert out[0] is LineSplitter.OVERLONG and out[1] == "ok"


def test_fault_disconnect_and_reconnect(rig):
    with open_port(rig.url("camera"), "camera", timeout=0.2) as camera:
        rig.control.disconnect("camera")
        camera.write(b"*IDN?\n")
        assert camera.readline() == b""
        rig.control.reconnect("camera")
        camera.write(b"*IDN?\n")
        assert camera.readline() == b"GONIO,CCD-512,SN0001,1.0\n"


def test_fault_garbled_reply_keeps_line_sync(rig):
    with open_port(rig.url("lamp"), "lamp") as lamp:
        rig.control.garble("lamp", 1)
        lamp.write(b"*IDN?\n")
        garbled = lamp.readline()
        assert garbled.endswith(b"\n") and garbled != b"GONIO,LPS-300,SN0001,1.0\n"
        lamp.write(b"*IDN?\n")
        assert lamp.readline() == b"GONIO,LPS-300,SN0001,1.0\n"


def test_fault_stall_delays_the_reply(rig):
    with open_port(rig.url("stage"), "stage", timeout=0.1) as stage:
        rig.control.stall("stage", 0.4)
        stage.write(b"TE?\r")
        assert stage.readline() == b""  # client times out
        stage.timeout = 2.0
        assert stage.readline() == b"0\r\n"  # the late reply still arrives


def test_fault_stage_hits_hardware_limit(rig):
    with open_port(rig.url("stage"), "stage") as stage:
        stage.write(b"1MO;1PA-40;1WS;1MD?\r")
        assert stage.readline() == b"1\r\n"  # the first move is done before the fault is armed
        rig.control.hit_limit(1)
        stage.write(b"1PA-80;1WS;1TP\r")
        position = float(stage.readline())
        assert position == pytest.approx(-60.0, abs=0.01)  # tripped half way
        stage.write(b"TB?\r")
        assert stage.readline().decode().split(", ")[0::2] == ["105", "NEGATIVE HARDWARE LIMIT DETECTED\r\n"]


def test_fault_camera_execution_error(rig):
    with open_port(rig.url("camera"), "camera") as camera:
        rig.control.camera_fault(True)
        camera.write(b"ACQ;SYST:ERR?\n")
        assert camera.readline() == b'-200,"Execution error;camera fault"\n'
        rig.control.clear_faults()
        camera.write(b"ACQ;SYST:ERR?\n")
        assert camera.readline() == b'0,"No error"\n'


def test_fault_injection_rejects_bad_names(rig):
    with pytest.raises(ValueError, match="device"):
        rig.control.disconnect("printer")
    with pytest.raises(ValueError, match="axis"):
        rig.control.hit_limit(4)


def test_true_state_tracks_geometry_and_clock(rig):
    rig.channels["stage"].process("MO;1PA-50;3PA90;1WS;3WS")
    truth = rig.control.true_state()
    assert truth.theta_r == pytest.approx(50.0, abs=0.01) and truth.phi_r == 180.0
    assert truth.theta_i == pytest.approx(45.0, abs=0.01) and truth.phi_i == pytest.approx(90.0, abs=0.01)
    assert truth.moving == (False, False, False)
    # Lambertian rho = 0.9: radiance = E0 * 0.9 cos(45) / pi (cone average: 3e-4).
    assert truth.radiance_w_m2_sr == pytest.approx(
        truth.irradiance_w_m2 * 0.9 * np.cos(np.radians(45)) / np.pi, rel=5e-4)
    t0 = rig.control.now()
    rig.control.advance(10.0)
    assert rig.control.now() == pytest.approx(t0 + 10.0)


def test_realtime_mode_takes_wall_time():
    with EmulatedRig(lambert, seed=1, name="realtime-test", clock_mode="realtime") as r:
        r.start(pty=False)
        with open_port(r.url("camera"), "camera") as camera:
            start = time.monotonic()
            camera.write(b"EXP 0.3;ACQ;*OPC?\n")
            assert camera.readline() == b"1\n"
            # 0.3 s exposure + 0.05 s readout; scheduling jitter only adds time.
            assert time.monotonic() - start >= 0.34


@pytest.mark.parametrize("transport", ["url", "tcp"])
def test_a_long_reply_streams_at_the_line_rate_in_real_time(transport):
    """Real-time mode: a block reply flows as a 115200-baud line carries it (the first bytes
    within a fraction of a second, the last after its transfer time), instead of arriving
    in one burst after the whole transfer time (FRAME? gave its first byte after 42.7 s)."""
    with EmulatedRig(lambert, seed=1, name=f"stream-{transport}", clock_mode="realtime", lamp_warm=True) as r:
        r.start(pty=False, tcp=transport == "tcp")
        url = r.url("camera") if transport == "url" else r.addresses()["camera"]["tcp"]
        with open_port(url, "camera") as camera:
            camera.write(b"EXP 0.01;ROI 0,0,200,100;ACQ;*OPC?\n")
            assert camera.readline() == b"1\n"
            start = time.monotonic()
            camera.write(b"ROI:DATA?\n")  # 40000 bytes of pixels: 3.5 s of line time
            first = camera.read(1)
            first_at = time.monotonic() - start
            rest = b""
            while len(first + rest) < 40008:
                rest += camera.read(40008 - len(first + rest))
            total = time.monotonic() - start
    assert first == b"#" and first_at < 0.5
    transfer = 40008 * 10 / 115200  # 3.47 s
    assert transfer - 0.1 <= total <= transfer + 1.0  # scheduling only adds time


def test_two_rigs_with_the_same_name_are_refused():
    with EmulatedRig(lambert, name="dup") as a, EmulatedRig(lambert, name="dup") as b:
        a.start(pty=False)
        with pytest.raises(ValueError, match="already running"):
            b.start(pty=False)


def test_bad_brdf_values_become_execution_errors_not_crashes():
    nan_brdf = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, np.nan)
    with EmulatedRig(nan_brdf, seed=1, name="nan-test", lamp_warm=True) as r:
        r.start(pty=False)
        with open_port(r.url("camera"), "camera") as camera:
            camera.write(b"ACQ;SYST:ERR?\n")
            assert camera.readline().startswith(b'-200,"Execution error;the sample BRDF gave radiance nan')
            camera.write(b"*IDN?\n")  # the line still works
            assert camera.readline() == b"GONIO,CCD-512,SN0001,1.0\n"


# -- robustness: no exception from one line stops a line (docs/protocol.md "Robustness") --------

class _FirmwareWithBrokenErrorPath:
    """A firmware whose handle_line, overlong_line AND internal_error all raise on "boom"."""

    reply_terminator = b"\r\n"

    def __init__(self, inner) -> None:
        self.inner = inner

    def handle_line(self, line: str) -> bytes:
        if "boom" in line:
            raise RuntimeError("firmware bug")
        return self.inner.handle_line(line)

    def overlong_line(self) -> bytes:
        raise RuntimeError("bug in overlong_line")

    def internal_error(self, error: Exception) -> bytes:
        raise OverflowError("bug in the error path")


def test_sim_clock_refuses_non_finite_times():
    from drivers.emulator.clock import SimClock

    clock = SimClock()
    clock.wait_until(2.0)
    for bad in (float("inf"), float("-inf"), float("nan")):
        with pytest.raises(ValueError, match="finite"):
            clock.wait_until(bad)
        with pytest.raises(ValueError, match="finite"):
            clock.advance(bad)
    with pytest.raises(ValueError, match="finite"):
        SimClock(start=float("inf"))
    assert clock.now() == 2.0  # every refusal left the clock where it was
    late = SimClock(start=1e308)
    with pytest.raises(ValueError, match="finite"):
        late.advance(1e308)  # each finite, but the sum overflows to inf
    assert late.now() == 1e308


def test_channel_survives_a_firmware_whose_error_path_raises():
    from drivers.emulator.clock import SimClock
    from drivers.emulator.stage_firmware import Esp300Firmware
    from drivers.emulator.transports import DeviceChannel

    clock = SimClock()
    firmware = _FirmwareWithBrokenErrorPath(Esp300Firmware(clock, np.random.default_rng(0)))
    channel = DeviceChannel("stage", firmware, clock, 19200)
    assert channel.process("boom") == b""
    error = channel.last_internal_error
    assert isinstance(error, OverflowError)  # the error path's exception is recorded ...
    assert isinstance(error.__context__, RuntimeError)  # ... with the firmware's as its context
    assert channel.process(LineSplitter.OVERLONG) == b""
    assert channel.process("VE?") == b"ESP300 Version 3.08 09/09/02\r\n"  # the line still answers
    assert channel.lines_processed == 3


@pytest.mark.parametrize("kind", ["pty", "tcp", "url"])
def test_serving_loops_survive_any_exception_from_one_line(rig, kind):
    channel = rig.channels["stage"]
    channel.firmware = _FirmwareWithBrokenErrorPath(rig.stage)
    process = channel.process

    def process_that_raises(line):  # beyond what DeviceChannel.process contains
        if line == "kaboom":
            raise MemoryError("not a firmware error")
        return process(line)

    channel.process = process_that_raises
    with open_port(rig.addresses()["stage"][kind], "stage") as stage:
        stage.write(b"boom\r" + b"1" * 5000 + b"\rkaboom\rVE?\r")
        assert stage.readline() == b"ESP300 Version 3.08 09/09/02\r\n"
        assert isinstance(channel.last_internal_error, MemoryError)
        stage.write(b"boom;VE?\rVE?\r")  # and again: the serving thread is alive
        assert stage.readline() == b"ESP300 Version 3.08 09/09/02\r\n"
        assert isinstance(channel.last_internal_error, OverflowError)


def test_bytes_above_0x7f_reach_the_firmware_as_escapable_surrogates():
    line = next(iter(LineSplitter().feed(b"EX\xe9P 1\r")))
    assert line == "EX\udce9P 1"
    assert line.encode("ascii", errors="surrogateescape") == b"EX\xe9P 1"  # byte-faithful


@pytest.mark.parametrize("kind", ["tcp", "url"])
def test_non_ascii_bytes_never_lose_scpi_replies(rig, kind):
    with open_port(rig.addresses()["camera"][kind], "camera") as camera:
        camera.write(b"EX\xe9P 1;*IDN?\n\xff\x00\x1b\n")
        assert camera.readline() == b"GONIO,CCD-512,SN0001,1.0\n"
        camera.write(b"SYST:ERR?;:SYST:ERR?;ERR?\n")
        reply = camera.readline()
        # Each received byte outside printable ASCII is quoted as \xNN: the reply is ASCII.
        assert reply == (b'-100,"Command error;\'EX\\xe9P 1\'";'
                         b'-100,"Command error;\'\\xff\\x00\\x1b\'";0,"No error"\n')

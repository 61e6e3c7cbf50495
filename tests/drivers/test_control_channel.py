"""The emulated rig from outside its process (drivers/emulator/control.py; docs/emulator.md,
"Control from outside"): the JSON-lines control channel and the traffic log."""
from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys

import numpy as np
import pytest
import serial
from emulator_process import banner

from drivers.emulator.control import ControlServer, TrafficLog
from drivers.emulator.rig import EmulatedRig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1 / np.pi)


class Client:
    """A control-channel client: one JSON request per line, one reply per line."""

    def __init__(self, port: int) -> None:
        self.socket = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.file = self.socket.makefile("rwb")

    def send_raw(self, line: bytes) -> dict:
        self.file.write(line + b"\n")
        self.file.flush()
        return json.loads(self.file.readline())

    def __call__(self, op: str, **args) -> dict:
        return self.send_raw(json.dumps({"op": op, "args": args}).encode())

    def close(self) -> None:
        self.file.close()
        self.socket.close()


@pytest.fixture
def served():
    rig = EmulatedRig(lambert, seed=4, motors_on=True, lamp_warm=True)
    server = ControlServer(rig, 0)
    client = Client(server.port)
    yield rig, client
    client.close()
    server.close()


def test_time_passes_and_the_true_state_is_read_over_the_channel(served):
    rig, control = served
    before = control("now")["result"]
    assert control("advance", seconds=5.0) == {"ok": True, "result": None}
    assert control("now")["result"] == pytest.approx(before + 5.0)
    rig.channels["stage"].process("1PA20")
    control("advance", seconds=10.0)
    state = control("true_state")["result"]
    assert state["positions_deg"][0] == pytest.approx(20.0, abs=0.01)  # where the camera arm really is
    assert state["moving"] == [False, False, False] and state["lamp_output"] > 0.9


def test_the_wall_clock_is_paused_sped_up_and_read_over_the_channel():
    rig = EmulatedRig(lambert, seed=4, clock_mode="wall", speed=1.0)
    server = ControlServer(rig, 0)
    control = Client(server.port)
    try:
        assert control("pause") == {"ok": True, "result": None}
        held = control("clock")["result"]
        assert (held["mode"], held["speed"], held["paused"]) == ("wall", 1.0, True)
        assert control("now")["result"] == held["time_s"]  # paused: the wall clock does not count
        control("advance", seconds=3.0)
        assert control("now")["result"] == pytest.approx(held["time_s"] + 3.0)
        assert control("set_speed", speed=500.0)["ok"] and control("resume")["ok"]
        assert control("now")["result"] > held["time_s"] + 3.0
        refused = control("set_speed", speed=-1)
        assert not refused["ok"] and "speed must be a finite number > 0" in refused["error"]
    finally:
        control.close()
        server.close()


def test_faults_injected_from_outside_reach_the_instruments(served):
    rig, control = served
    assert control("camera_fault", active=True)["ok"]
    assert rig.channels["camera"].process("*TST?") == b"1\n"
    assert control("burn_out_lamp")["ok"]
    assert rig.channels["lamp"].process("STAT:LAMP?") == b"FAULT\n"
    assert control("disconnect", device="stage")["ok"]
    assert rig.channels["stage"].process("VE?") == b""
    assert control("clear_faults")["ok"] and control("reconnect", device="stage")["ok"]
    assert rig.channels["stage"].process("VE?").startswith(b"ESP300")
    assert rig.channels["camera"].process("*TST?") == b"0\n"


@pytest.mark.parametrize("line, words", [
    (b"advance 5", "not a JSON object"),
    (b'{"op": "explode"}', "op 'explode': expected one of"),
    (b'{"op": "advance", "args": {"minutes": 5}}', "unknown argument(s) ['minutes']; it takes ['seconds']"),
    (b'{"op": "stall", "args": {"device": "printer", "seconds": 1}}', "device must be one of"),
    (b'{"op": "garble", "args": {"device": "camera", "replies": -1}}', "replies must be >= 0"),
])
def test_a_bad_request_is_answered_with_what_was_expected(served, line, words):
    rig, control = served
    reply = control.send_raw(line)
    assert reply["ok"] is False and words in reply["error"]
    assert control("now")["ok"]  # the channel still serves


def test_the_traffic_log_holds_every_line_with_its_times(tmp_path):
    rig = EmulatedRig(lambert, seed=4, motors_on=True, lamp_warm=True)
    log = TrafficLog(tmp_path / "traffic.jsonl")
    for channel in rig.channels.values():
        channel.traffic = log
    rig.channels["camera"].process("EXP 0.02;ACQ;ROI:STAT?")
    rig.channels["camera"].process("FRAME?")
    rig.channels["stage"].process("1TP?")
    log.close()
    entries = [json.loads(line) for line in (tmp_path / "traffic.jsonl").read_text().splitlines()]
    assert [e["device"] for e in entries] == ["camera", "camera", "stage"]
    assert entries[0]["received"] == "EXP 0.02;ACQ;ROI:STAT?" and entries[0]["replied"].count(",") == 3
    assert entries[1]["replied"] == "#6491520<491520 bytes>\\x0a"  # the frame's block: its header and size
    assert entries[2]["replied"].endswith("\\x0d\\x0a")
    assert entries[0]["sim_time"] < entries[1]["sim_time"] <= entries[2]["sim_time"]
    assert entries[2]["wall_time"].endswith("+00:00")


def test_gonio_emulator_is_controlled_from_another_process(tmp_path):
    """The command line serves the control channel and writes the traffic log; a client in
    this process drives the camera over TCP and lets the emulator's time pass."""
    traffic = tmp_path / "traffic.jsonl"
    process = subprocess.Popen(
        [sys.executable, "-m", "gonio", "emulator", "--sample", "lambert:rho=0.5", "--tcp", "--no-pty",
         "--control", "0", "--log-traffic", str(traffic)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = banner(process)
        assert "wall clock x1 (jumps ahead while a client waits on the rig)" in lines[0]
        fields = {tuple(l.split()[:2]): l.split()[2] for l in lines if l.startswith(("camera", "control"))}
        control = Client(int(fields[("control", "tcp")].rsplit(":", 1)[1]))
        start = control("now")["result"]
        control("advance", seconds=60.0)
        with serial.serial_for_url(fields[("camera", "tcp")], baudrate=115200, timeout=5) as camera:
            camera.write(b"SIM:TIME?\n")
            assert float(camera.readline()) >= start + 60.0
        control.close()
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=60)
        assert process.returncode == 0, err
        logged = [json.loads(line) for line in traffic.read_text().splitlines()]
        assert logged[-1]["device"] == "camera" and logged[-1]["received"] == "SIM:TIME?"
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


@pytest.mark.parametrize("argv, words", [
    (["--speed", "0"], "--speed 0: expected simulated seconds per wall second, a number > 0"),
    (["--speed", "nan"], "--speed nan: expected simulated seconds per wall second"),
    (["--clock", "event", "--realtime"], "--realtime and --clock event ask for two clocks"),
])
def test_bad_clock_options_are_refused_before_anything_starts(capsys, argv, words):
    from gonio.cli import main

    assert main(["emulator", "--no-pty", "--tcp", *argv]) == 2
    assert words in capsys.readouterr().err


def test_a_control_port_out_of_range_is_refused_before_anything_starts(capsys):
    from gonio.cli import main

    assert main(["emulator", "--no-pty", "--tcp", "--control", "70000"]) == 2
    assert "--control 70000: expected a TCP port 0..65535" in capsys.readouterr().err

"""``gonio emulator``: starts the rig with a registry model, prints addresses, stops cleanly."""
from __future__ import annotations

import signal
import subprocess
import sys

import pytest
import serial
from emulator_process import banner

from gonio.cli import CLIError, build_parser, main
from gonio.cli.emulator import _port_spec, format_addresses


def test_parser_defaults_and_port_specs():
    args = build_parser().parse_args(["emulator", "--sample", "oren-nayar:sigma=30,rho=0.9"])
    assert (args.seed, args.clock, args.speed, args.pty, args.tcp, args.min_separation) == (0, None, 1.0, True, False, 5.0)
    assert _port_spec("5000") == {"stage": 5000, "camera": 5001, "lamp": 5002}
    assert _port_spec("camera=7001") == {"camera": 7001}
    with pytest.raises(CLIError, match="tcp-ports"):
        _port_spec("printer=1")
    text = format_addresses({"stage": {"pty": "/dev/pts/9", "tcp": "socket://127.0.0.1:1"}})
    assert text.splitlines() == ["stage   pty  /dev/pts/9", "stage   tcp  socket://127.0.0.1:1"]


def _default_sigint() -> None:
    """Child side of Popen: SIGINT back to its default and unblocked, whatever the test
    process inherited from its runner, so that Python installs KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def test_gonio_emulator_serves_a_registry_model_and_stops_on_interrupt(tmp_path):
    process = subprocess.Popen(
        [sys.executable, "-m", "gonio", "emulator", "--sample", "oren-nayar:sigma=30,rho=0.9", "--tcp",
         "--link-dir", str(tmp_path), "--seed", "3"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint,
    )
    try:
        lines = banner(process)
        addresses = {tuple(l.split()[:2]): l.split()[2] for l in lines if l.startswith(("stage", "camera", "lamp"))}
        assert set(addresses) == {(d, k) for d in ("stage", "camera", "lamp") for k in ("pty", "tcp")}
        assert addresses[("stage", "pty")] == str(tmp_path / "gonio-stage")
        with serial.serial_for_url(addresses[("stage", "pty")], baudrate=19200, timeout=5) as stage:
            stage.write(b"VE?\r")
            assert stage.readline() == b"ESP300 Version 3.08 09/09/02\r\n"
        with serial.serial_for_url(addresses[("camera", "tcp")], baudrate=115200, timeout=5) as camera:
            camera.write(b"*IDN?\n")
            assert camera.readline() == b"GONIO,CCD-512,SN0001,1.0\n"
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
        assert process.returncode == 0, err
        assert "stopped" in out
        assert not (tmp_path / "gonio-stage").exists()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_gonio_emulator_rejects_unknown_model(capsys):
    assert main(["emulator", "--sample", "no-such-model"]) == 2
    assert "unknown model" in capsys.readouterr().err

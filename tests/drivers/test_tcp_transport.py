"""TCP transport: the socket options that keep a command-then-query exchange from stalling.

Speed itself is measured in benchmarks/bench_rig.py (ratios TCP/pty in one run); these
tests check the mechanism: Nagle's algorithm off on the client (``TCP_NODELAY``), no delayed
ACKs on the emulator (``TCP_QUICKACK``, Linux), and whole replies read in one call.
"""
from __future__ import annotations

import socket
import sys

import numpy as np
import pytest

from drivers.emulator.rig import EmulatedRig
from drivers.emulator.transports import _quick_ack
from drivers.errors import TransportError
from drivers.serial_line import SerialLine


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1.0 / np.pi)


@pytest.fixture
def tcp_rig():
    with EmulatedRig(lambert, seed=4, name="tcp-options") as rig:
        yield rig, rig.start(pty=False, tcp=True)


def test_serial_line_switches_nagle_off_on_tcp_ports(tcp_rig):
    _, addresses = tcp_rig
    with SerialLine(addresses["camera"]["tcp"], baudrate=115200, timeout=1.0) as line:
        sock = line._port._socket
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0
        line.write("EXP 0.02")  # a command without a reply, then a query: the stalling pair
        assert line.query("SYST:ERR?") == '0,"No error"'
        assert line.query("EXP?;GAIN?;SHUT?") == "0.02;1;OPEN"


def test_serial_line_leaves_other_ports_alone():
    with SerialLine("loop://", baudrate=9600, timeout=0.2) as line:
        assert line._socket is None
        line.write("hello")
        assert line.read_line() == "hello"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="TCP_QUICKACK is a Linux socket option")
def test_quick_ack_is_set_on_the_emulator_side():
    server = socket.create_server(("127.0.0.1", 0))
    client = socket.create_connection(server.getsockname())
    conn, _ = server.accept()
    with server, client, conn:
        _quick_ack(conn)
        assert conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_QUICKACK) != 0


def test_a_closed_connection_is_a_transport_error(tcp_rig):
    rig, addresses = tcp_rig
    line = SerialLine(addresses["stage"]["tcp"], baudrate=19200, write_termination="\r",
                      read_termination="\r\n", timeout=1.0)
    assert line.query("VE?") == "ESP300 Version 3.08 09/09/02"
    rig.close()  # the emulator goes away: the peer closes the connection
    with pytest.raises(TransportError, match="closed by the peer|read failed"):
        for _ in range(3):
            line.query("VE?", retries=0, timeout=0.5)
    line.close()


def test_one_controller_per_instrument(tcp_rig):
    """Two programs driving one instrument in turn corrupt each other's measurements (two
    'gonio run' on one emulator recorded wrong rows): a second TCP client is cut off, a
    second opener of the pseudo-terminal refused, and the instrument is free again once
    the first controller has closed."""
    _, addresses = tcp_rig
    url = addresses["camera"]["tcp"]
    with SerialLine(url, baudrate=115200, timeout=1.0, retries=0) as first:
        assert first.query("EXP?") == "0.01"
        second = SerialLine(url, baudrate=115200, timeout=1.0, retries=0)
        with pytest.raises(TransportError, match="serves one controller at a time"):
            second.query("EXP?")
        second.close()
        assert first.query("EXP?") == "0.01"  # the first controller is undisturbed
    with SerialLine(url, baudrate=115200, timeout=1.0) as next_one:
        assert next_one.query("EXP?") == "0.01"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pseudo-terminals and flock as on Linux")
def test_a_pseudo_terminal_has_one_controller():
    with EmulatedRig(lambert, seed=4, name="pty-exclusive") as rig:
        path = rig.start(pty=True)["camera"]["pty"]
        with SerialLine(path, baudrate=115200, timeout=1.0) as first:
            with pytest.raises(TransportError, match="another program holds the port"):
                SerialLine(path, baudrate=115200, timeout=1.0)
            assert first.query("EXP?") == "0.01"
        with SerialLine(path, baudrate=115200, timeout=1.0) as again:
            assert again.query("EXP?") == "0.01"


def test_a_late_reply_costs_one_exchange_not_the_run(tcp_rig):
    """A reply that comes after its query timed out used to be read as the answer to the
    next query (4 of 5 runs stopped on one): the drivers resynchronise with a marker query
    (the ESP300's VE?, SCPI's *IDN?) and every command gets its own reply."""
    from drivers.esp300 import ESP300
    from drivers.errors import ResponseTimeout

    rig, addresses = tcp_rig
    stage = ESP300.open(addresses["stage"]["tcp"], timeout=0.2, retries=0)
    try:
        rig.control.stall("stage", 0.5)
        with pytest.raises(ResponseTimeout):
            stage.line.query("1TP?")  # its reply comes 0.3 s too late
        assert stage.line.query("TE?", timeout=2.0) == "0"  # not the late position
        assert stage.line.query("1TP?", timeout=2.0) == stage.line.query("1TP?")
    finally:
        stage.close()

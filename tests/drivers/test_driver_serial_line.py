"""SerialLine: terminators, deadlines, blocks, retries and failures (pyserial loop:// fake).

The loop:// URL of pyserial echoes what is written, which is all the line layer needs:
these tests pin its framing and its no-hang guarantees independently of any device.
The device round trips are in test_driver_esp300.py, test_driver_camera.py, ... against
the emulator.
"""
from __future__ import annotations

import time

import pytest

from drivers.errors import DriverError, ProtocolError, ResponseTimeout, TransportError
from drivers.serial_line import SerialLine

# A deadline of 0.15 s is long against the microseconds an in-process echo takes, and
# short enough that a hang would show as a test failure rather than a stall.
TIMEOUT = 0.15


@pytest.fixture
def line():
    with SerialLine("loop://", baudrate=9600, timeout=TIMEOUT, retries=1) as ln:
        yield ln


def test_line_round_trip_strips_terminator(line):
    line.write("*IDN?")
    assert line.read_line() == "*IDN?"
    assert line.transcript[-1][2] == b"*IDN?\n"


def test_crlf_reply_terminator_accepts_bare_lf_and_strips_cr():
    with SerialLine("loop://", baudrate=19200, write_termination="\r\n",
                    read_termination="\r\n", timeout=TIMEOUT) as ln:
        ln.write("1TP")
        assert ln.read_line() == "1TP"
        ln._port.write(b"30.00000\n")  # a bare LF still ends the line
        assert ln.read_line() == "30.00000"


def test_two_lines_in_one_read_are_split(line):
    line._port.write(b"first\nsecond\n")
    assert line.read_line() == "first"
    assert line.read_line() == "second"


def test_missing_reply_times_out_within_deadline(line):
    start = time.monotonic()
    with pytest.raises(ResponseTimeout) as info:
        line.read_line(command="TB?")
    elapsed = time.monotonic() - start
    # The deadline is total: no more than the timeout plus one poll interval (0.05 s).
    assert TIMEOUT <= elapsed < TIMEOUT + 0.1
    assert "TB?" in str(info.value) and isinstance(info.value, TimeoutError)


def test_partial_reply_is_reported_then_discarded(line):
    line._port.write(b"12.5")  # no terminator: a stalled device
    with pytest.raises(ResponseTimeout) as info:
        line.read_line(command="1TP")
    assert info.value.partial == b"12.5"
    # The late rest of that reply must not be taken for the next answer.
    line._port.write(b"00\n")
    line.write("next")
    assert line.read_line() == "next"


def test_commands_with_terminators_are_refused(line):
    with pytest.raises(ValueError, match="CR or LF"):
        line.write("EXP 1\nACQ")


def test_definite_length_block(line):
    line._port.write(b"#210" + bytes(range(10)) + b"\n")
    assert line.read_block() == bytes(range(10))


@pytest.mark.parametrize("reply", [b"#x5hello\n", b"#0\n", b"#2ab\n"])
def test_malformed_block_header_raises_protocol_error(line, reply):
    line._port.write(reply)
    with pytest.raises(ProtocolError):
        line.read_block()


def test_short_block_times_out(line):
    line._port.write(b"#3100" + b"x" * 50)
    with pytest.raises(ResponseTimeout):
        line.read_block()


def test_query_parses_and_retries_on_garbled_reply(line):
    calls = []

    def parse(text):
        calls.append(text)
        return float(text)

    assert line.query("2.5", parse=parse) == 2.5
    # loop:// echoes the query itself; a non-numeric echo is a garbled reply: retried
    # once (retries=1) and then reported, with the hook called before each retry.
    hook = []
    with pytest.raises(ProtocolError, match="unexpected reply"):
        line.query("abc", parse=float, recover=hook.append)
    assert len(hook) == 2


def test_recover_hook_can_replace_the_failure_with_a_device_error():
    class Refused(DriverError):
        pass

    def recover(exc):
        raise Refused("device says no")

    def reject(text):
        raise ValueError("not a number")

    with SerialLine("loop://", baudrate=9600, timeout=TIMEOUT, retries=3) as ln:
        with pytest.raises(Refused):
            ln.query("X?", parse=reject, recover=recover)
        assert ln.exchanges == 1  # the hook's error stops the retries at once


def test_closed_port_raises_transport_error(line):
    line.close()
    assert not line.is_open
    with pytest.raises(TransportError, match="closed"):
        line.write("x")
    with pytest.raises(TransportError):
        line.read_line()
    line.close()  # idempotent


def test_unopenable_port_raises_transport_error():
    with pytest.raises(TransportError, match="cannot open"):
        SerialLine("/dev/does-not-exist-gonio", baudrate=9600)


@pytest.mark.parametrize("kwargs", [{"timeout": 0}, {"timeout": -1}, {"retries": -1}])
def test_bad_settings_raise_value_error(kwargs):
    with pytest.raises(ValueError):
        SerialLine("loop://", baudrate=9600, **kwargs)

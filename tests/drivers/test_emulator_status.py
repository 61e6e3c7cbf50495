"""IEEE 488.2 status model and SCPI STATus registers of the emulated camera and lamp.

Exact command/reply pairs against docs/protocol.md, section 2 "Status reporting" (IEEE 488.2
sections 10 to 12, SCPI-1999 vol. 1 section 9 and vol. 2 section 20).
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.rig import EmulatedRig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1.0 / np.pi)


@pytest.fixture
def rig():
    return EmulatedRig(lambert, seed=3, lamp_warm=True, motors_on=True)


def ask(rig, device, line):
    return rig.channels[device].process(line).decode("ascii")


@pytest.mark.parametrize("device", ["camera", "lamp"])
def test_power_on_event_is_read_once_and_versions(rig, device):
    assert ask(rig, device, "*ESR?") == "128\n"  # PON, bit 7
    assert ask(rig, device, "*ESR?") == "0\n"  # reading clears it
    assert ask(rig, device, "SYST:VERS?;*STB?;*ESE?;*SRE?") == "1999.0;16;0;0\n"  # MAV: earlier replies wait
    assert ask(rig, device, "*TST?") == "0\n"


@pytest.mark.parametrize("line, bit, code", [
    ("FOO", 5, -113),               # command error, CME
    ("EXP 100", 4, -222),           # execution error, EXE
    ("*IDN?;*ESE?", 2, -440),       # query error, QYE: nothing may follow *IDN?'s reply
])
def test_each_error_class_sets_its_event_bit(rig, line, bit, code):
    ask(rig, "camera", "*CLS")
    reply = ask(rig, "camera", line)
    assert reply == ("GONIO,CCD-512,SN0001,1.0\n" if line.startswith("*IDN") else "")
    assert ask(rig, "camera", "*STB?") == "4\n"  # bit 2: the error queue is not empty
    assert ask(rig, "camera", "SYST:ERR:COUN?") == "1\n"
    assert ask(rig, "camera", "SYST:ERR?").startswith(f"{code},")
    assert ask(rig, "camera", "*ESR?") == f"{1 << bit}\n"
    assert ask(rig, "camera", "*STB?") == "0\n"


def test_queue_overflow_is_a_device_dependent_error(rig):
    ask(rig, "camera", "*CLS")
    for _ in range(17):
        ask(rig, "camera", "FOO")
    assert ask(rig, "camera", "*ESR?") == f"{(1 << 5) | (1 << 3)}\n"  # CME and DDE (-350)


def test_masks_and_service_request_summary(rig):
    ask(rig, "camera", "*CLS;*ESE 36;*SRE 255")
    assert ask(rig, "camera", "*ESE?;*SRE?") == "36;191\n"  # bit 6 of the SRE is ignored
    ask(rig, "camera", "EXP 100")  # EXE: not enabled in the ESE
    assert ask(rig, "camera", "*STB?") == f"{4 | 64}\n"  # queue bit 2 is enabled in the SRE -> MSS
    ask(rig, "camera", "*CLS;*SRE 32")
    ask(rig, "camera", "FOO")  # CME is enabled: ESB and MSS
    assert ask(rig, "camera", "*STB?") == f"{4 | 32 | 64}\n"
    ask(rig, "camera", "*ESE 256;*SRE -1")
    assert [ask(rig, "camera", "SYST:ERR?").split(",")[0] for _ in range(3)] == ["-113", "-222", "-222"]
    assert ask(rig, "camera", "*ESE?;*SRE?") == "36;32\n"  # unchanged by the refused values


def test_opc_reports_the_end_of_an_overlapped_exposure(rig):
    """docs/protocol.md's example: *OPC, *STB? polling, *ESR? (IEEE 488.2 12.5.2)."""
    ask(rig, "camera", "*CLS;*ESE 1;*SRE 32")
    t0 = rig.control.now()
    assert ask(rig, "camera", "EXP 0.5;ACQ;*OPC") == ""
    assert ask(rig, "camera", "*STB?;:STAT:OPER:COND?") == "0;16\n"  # MEASuring, OPC not yet set
    assert rig.control.now() - t0 < 0.01  # the status commands do not wait
    rig.control.advance(0.55)
    assert ask(rig, "camera", "*STB?;:STAT:OPER:COND?") == "96;0\n"  # ESB and MSS
    assert ask(rig, "camera", "*ESR?;*ESR?") == "1;0\n"
    assert ask(rig, "camera", "*OPC;*ESR?") == "1\n"  # nothing pending: OPC at once


def test_opc_query_and_wai_wait_for_the_exposure(rig):
    t0 = rig.control.now()
    ask(rig, "camera", "EXP 0.2;ACQ;*WAI")
    assert rig.control.now() - t0 == pytest.approx(0.25, abs=2e-3)  # exposure + readout + bytes
    ask(rig, "camera", "ACQ")
    assert ask(rig, "camera", "*OPC?") == "1\n"
    assert rig.control.now() - t0 == pytest.approx(0.5, abs=4e-3)


def test_operation_events_latch_transitions_through_the_filters(rig):
    ask(rig, "camera", "*CLS;:STAT:OPER:ENAB 16")
    ask(rig, "camera", "EXP 0.1;ACQ;*WAI")
    assert ask(rig, "camera", "STAT:OPER:COND?;*STB?") == "0;144\n"  # OPER summary (128) + MAV (16)
    assert ask(rig, "camera", "STAT:OPER?;:STAT:OPER:EVEN?") == "16;0\n"  # read and cleared
    ask(rig, "camera", "STAT:OPER:PTR 0;NTR 16")  # now only the end of an exposure latches
    ask(rig, "camera", "ACQ")
    assert ask(rig, "camera", "STAT:OPER:EVEN?") == "0\n"  # started, not ended
    ask(rig, "camera", "*WAI")
    assert ask(rig, "camera", "STAT:OPER:EVEN?;PTR?;NTR?") == "16;0;16\n"
    ask(rig, "camera", "STAT:PRES")
    assert ask(rig, "camera", "STAT:OPER:ENAB?;PTR?;NTR?") == "0;32767;0\n"
    ask(rig, "camera", "STAT:OPER:ENAB 32768")  # bit 15 does not exist
    assert ask(rig, "camera", "SYST:ERR?").startswith("-222,")


def test_saturated_roi_is_questionable(rig):
    rig.control.true_state()
    ask(rig, "camera", "EXP 0.001;ACQ")
    assert ask(rig, "camera", "STAT:QUES:COND?") == "0\n"
    ask(rig, "camera", "EXP 5;ACQ")  # 5 s on a white sample: the ADC saturates
    assert ask(rig, "camera", "ROI:STAT?").split(",")[3].strip() != "0"
    assert ask(rig, "camera", "STAT:QUES:COND?;:STAT:QUES?") == "512;512\n"
    ask(rig, "camera", "ROI 0,0,4,4")  # a dark corner outside the sample's image
    assert ask(rig, "camera", "STAT:QUES:COND?") == "0\n"


def test_rst_keeps_the_status_and_cls_keeps_the_enables(rig):
    ask(rig, "camera", "*CLS;*ESE 1;*SRE 32;:STAT:OPER:ENAB 16;:EXP 0.5;ACQ;*OPC")
    ask(rig, "camera", "*RST")  # abandons the exposure and cancels the armed *OPC
    rig.control.advance(1.0)
    assert ask(rig, "camera", "*ESR?;*ESE?;*SRE?;:STAT:OPER:ENAB?;:EXP?") == "0;1;32;16;0.01\n"
    ask(rig, "camera", "FOO;*CLS")
    assert ask(rig, "camera", "*ESR?;SYST:ERR?;*ESE?;*SRE?;:STAT:OPER:ENAB?") == '0;0,"No error";1;32;16\n'


def test_camera_fault_fails_the_self_test(rig):
    rig.control.camera_fault(True)
    assert ask(rig, "camera", "*TST?") == "1\n"
    rig.control.camera_fault(False)
    assert ask(rig, "camera", "*TST?") == "0\n"


def test_lamp_settling_power_and_burn_out(rig):
    fresh = EmulatedRig(lambert, seed=3)
    assert ask(fresh, "lamp", "STAT:OPER:COND?;:STAT:QUES:COND?") == "0;0\n"  # off: nothing to report
    ask(fresh, "lamp", "OUTP ON")
    assert ask(fresh, "lamp", "STAT:OPER:COND?;:STAT:QUES:COND?") == "2;8\n"  # SETTling, POWer
    fresh.control.advance(300.0)
    assert ask(fresh, "lamp", "STAT:OPER:COND?") == "2\n"  # 2 % deficit, 120 s: 0.1 % after 366 s
    fresh.control.advance(70.0)
    assert ask(fresh, "lamp", "STAT:OPER:COND?;:STAT:QUES:COND?;:STAT:OPER?") == "0;0;2\n"
    fresh.control.burn_out_lamp()
    assert ask(fresh, "lamp", "STAT:QUES:COND?;*TST?;*OPT?") == f"{512 | 8};1;0\n"
    assert ask(rig, "lamp", "STAT:OPER:COND?;:STAT:QUES:COND?;*OPC;*ESR?") == "0;0;129\n"  # warm lamp; PON + OPC

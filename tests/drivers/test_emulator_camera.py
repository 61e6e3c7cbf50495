"""Emulated CCD camera: exact SCPI command/reply pairs (docs/protocol.md section 2)."""
from __future__ import annotations

import re

import numpy as np
import pytest

from drivers.emulator.rig import EmulatedRig
from drivers.emulator.world import Optics


def lambert(rho=1.0):
    return lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, rho / np.pi)


@pytest.fixture
def rig():
    return EmulatedRig(lambert(), seed=2, lamp_warm=True, motors_on=True)


def ask(rig, device, line):
    reply = rig.channels[device].process(line)
    return reply if device == "camera" and reply.startswith(b"#") else reply.decode("ascii")


def errors(rig, device="camera"):
    out = []
    while not (reply := ask(rig, device, "SYST:ERR?")).startswith("0,"):
        out.append(reply.strip())
    assert reply == '0,"No error"\n'
    return out


def test_identity_info_and_defaults(rig):
    assert ask(rig, "camera", "*IDN?") == "GONIO,CCD-512,SN0001,1.0\n"
    assert ask(rig, "camera", "SENS:INFO?") == "512,480,12,15,150,1828.8\n"
    assert ask(rig, "camera", "EXP?;GAIN?;SHUT?;ROI?") == "0.01;1;OPEN;0,0,512,480\n"
    assert ask(rig, "camera", "*OPC?") == "1\n"
    assert ask(rig, "camera", "TEMP?") == "25\n"


def test_settings_long_and_short_forms_case_insensitive(rig):
    assert ask(rig, "camera", "EXPOSURE 0.025") == ""
    assert ask(rig, "camera", "exp?") == "0.025\n"
    ask(rig, "camera", ":GAIN 2.5;SHUTTER CLOSE;roi 10,20,30,40")
    assert ask(rig, "camera", "GAIN?;SHUT?;ROI?") == "2.5;CLOSE;10,20,30,40\n"
    ask(rig, "camera", "EXP MAX;GAIN MIN")
    assert ask(rig, "camera", "EXP?;GAIN?") == "60;1\n"
    ask(rig, "camera", "*RST")
    assert ask(rig, "camera", "EXP?;GAIN?;SHUT?;ROI?") == "0.01;1;OPEN;0,0,512,480\n"
    assert errors(rig) == []


def test_errors_are_queued_and_failing_queries_reply_nothing(rig):
    assert ask(rig, "camera", "EXP 100") == ""
    assert ask(rig, "camera", "ACQ?") == ""
    assert ask(rig, "camera", "ROI:STAT?") == ""  # no frame yet
    assert ask(rig, "camera", "FOO 1") == ""
    assert ask(rig, "camera", "EXP") == ""
    assert ask(rig, "camera", "EXP abc") == ""
    assert ask(rig, "camera", "ROI 0,0,600,10") == ""
    assert ask(rig, "camera", "ROI 1,2,3") == ""
    assert ask(rig, "camera", "ACQ 5") == ""
    assert [e.split(",")[0] for e in errors(rig)] == ["-222", "-113", "-221", "-113", "-109", "-104", "-222",
                                                      "-109", "-108"]
    ask(rig, "camera", "EXP 100")
    assert ask(rig, "camera", "SYST:ERR?") == '-222,"Data out of range;EXP must be within 1e-05..60, got 100"\n'
    # A bad unit does not stop the good ones of the same line.
    assert ask(rig, "camera", "BAD?;EXP?") == "0.01\n"
    ask(rig, "camera", "*CLS")
    assert errors(rig) == []


def test_error_queue_overflow_reports_minus_350(rig):
    for _ in range(20):
        ask(rig, "camera", "FOO")
    codes = [e.split(",")[0] for e in errors(rig)]
    assert len(codes) == 16 and codes[-1] == "-350" and set(codes[:-1]) == {"-113"}


def test_acq_takes_exposure_plus_readout_in_simulated_time(rig):
    t0 = rig.control.now()
    ask(rig, "camera", "EXP 0.5;ACQ")
    # ACQ is overlapped: the line returns after its transfer time, 12 bytes at 115200 baud.
    assert rig.control.now() - t0 == pytest.approx(12 * 10 / 115200, abs=1e-9)
    # The next device command waits for the 0.5 s exposure and the 50 ms readout, then its
    # own 5 + 2 bytes ("EXP?" + LF, "0.5" + LF ... = 5 in, 4 out) take their transfer time.
    assert ask(rig, "camera", "EXP?") == "0.5\n"
    assert rig.control.now() - t0 == pytest.approx(0.55 + 9 * 10 / 115200, abs=1e-9)


def test_frame_block_matches_roi_statistics(rig):
    ask(rig, "camera", "EXP 0.02;ACQ;ROI 200,180,60,50")
    block = ask(rig, "camera", "FRAME?")
    assert block[:8] == b"#6491520" and block[-1:] == b"\n" and len(block) == 8 + 491520 + 1
    frame = np.frombuffer(block[8:-1], dtype="<u2").reshape(480, 512)
    window = frame[180:230, 200:260].astype(float)
    mean, std, count, saturated = ask(rig, "camera", "ROI:STAT?").strip().split(",")
    assert float(mean) == pytest.approx(window.mean(), abs=5e-5)
    assert float(std) == pytest.approx(window.std(ddof=1), abs=5e-5)
    assert (int(count), int(saturated)) == (3000, 0)
    assert re.fullmatch(r"\d+\.\d{4},\d+\.\d{4},\d+,\d+\n", ask(rig, "camera", "ROI:STAT?"))


def test_frame_shows_foreshortened_sample_on_dark_background(rig):
    ask(rig, "stage", "1PA-60;1WS")  # theta_r = 60 deg, lamp at theta_i = 45 (home)
    ask(rig, "camera", "EXP 0.05;ACQ")
    frame = np.frombuffer(ask(rig, "camera", "FRAME?")[8:-1], dtype="<u2").reshape(480, 512).astype(float)
    bright = frame > 300  # background ~100 DN dark offset; sample several hundred DN
    cols = bright[240].sum()
    rows = bright[:, 256].sum()
    size = Optics().sample_size_px  # 277.8 pixels at normal view
    # Partially covered edge pixels may fall either side of the threshold: +-2 pixels.
    assert abs(cols - size * 0.5) <= 2 and abs(rows - size) <= 2
    assert abs(frame[10:50, 10:50].mean() - 100.0) < 1.0  # dark background: offset + dark current


def test_shutter_closed_gives_dark_frames(rig):
    ask(rig, "camera", "SHUT CLOSE;EXP 0.05;ROI 206,190,100,100;ACQ")
    mean, std, _, _ = map(float, ask(rig, "camera", "ROI:STAT?").split(","))
    # Offset 100 DN + 20 e-/s * 0.05 s * 0.1 DN/e- = 100.1 DN; noise 0.8 DN (read noise).
    assert mean == pytest.approx(100.1, abs=0.1) and 0.6 < std < 1.1


def test_radiance_of_lambertian_sample_matches_truth(rig):
    ask(rig, "stage", "1PA20;1WS")
    ask(rig, "camera", "EXP 0.03;ROI 206,190,100,100;ACQ")
    mean = float(ask(rig, "camera", "ROI:STAT?").split(",")[0])
    expected = rig.control.expected_dn(0.03)
    # Sources of difference: PRNU averages out over 10^4 pixels (<0.01 %), DSNU is tiny,
    # lamp flicker is 0.05 % rms and drift is inside expected_dn: 0.3 % covers 6 sigma.
    assert mean == pytest.approx(expected, rel=0.003)
    truth = rig.control.true_state()
    # White Lambertian at theta_i = 45 deg: <f cos theta_i> = cos(45)/pi up to the cone average (3e-4).
    assert truth.reflectance_factor == pytest.approx(np.cos(np.radians(45)) / np.pi, rel=5e-4)


def test_white_lambertian_reaches_mid_range_in_10_to_100_ms():
    rig = EmulatedRig(lambert(1.0), seed=4, lamp_warm=True, motors_on=True)
    ask(rig, "stage", "2PA10;2WS")  # near-normal incidence (the camera at 0 needs >= 5 deg)
    for exposure in (0.01, 0.1):
        ask(rig, "camera", f"EXP {exposure};ROI 206,190,100,100;ACQ")
        mean = float(ask(rig, "camera", "ROI:STAT?").split(",")[0])
        if exposure == 0.01:
            assert mean < 2048
        else:
            assert mean > 2048


def test_gain_scales_signal_above_offset(rig):
    ask(rig, "camera", "EXP 0.01;ROI 206,190,100,100;GAIN 1;ACQ")
    m1 = float(ask(rig, "camera", "ROI:STAT?").split(",")[0]) - 100.0
    ask(rig, "camera", "GAIN 3;ACQ")
    m3 = float(ask(rig, "camera", "ROI:STAT?").split(",")[0]) - 100.0
    assert m3 / m1 == pytest.approx(3.0, rel=0.005)  # flicker 0.05 % and shot noise of the mean


def test_camera_replies_are_reproducible_from_seed():
    def session(seed):
        rig = EmulatedRig(lambert(0.5), seed=seed, lamp_warm=True, motors_on=True)
        ask(rig, "stage", "1PA30;1WS")
        return [ask(rig, "camera", "EXP 0.02;ROI 230,220,50,40;ACQ;ROI:STAT?") for _ in range(3)]

    assert session(7) == session(7)
    assert session(7) != session(8)


# -- strict parameters and printable error texts (docs/protocol.md section 2, "Errors") --------

@pytest.mark.parametrize(
    "line, code",
    [
        ("ROI ++1,2,3,4", "-104"),  # a doubled sign is no integer (was an internal -200)
        ("ROI 1.5,2,3,4", "-104"),
        ("ROI 1e2,2,3,4", "-104"),
        ("ROI 1,2,3,\u0664", "-104"),  # ARABIC-INDIC DIGIT FOUR is no ASCII digit
        ("ROI 1,,3,4", "-104"),
        ("ROI -1,0,10,10", "-222"),  # an integer, outside the sensor
        ("ROI 0,-1,10,10", "-222"),
        ("ROI 0,0,0,10", "-222"),
        ("ROI 1,2,3," + "9" * 30, "-222"),
    ],
)
def test_roi_parameters_are_strict_integers_inside_the_sensor(rig, line, code):
    assert ask(rig, "camera", line) == ""
    assert [e.split(",")[0] for e in errors(rig)] == [code]
    assert ask(rig, "camera", "ROI?") == "0,0,512,480\n"


def test_roi_accepts_signs_and_leading_zeros(rig):
    ask(rig, "camera", "ROI +10,0020,+30,40")
    assert ask(rig, "camera", "ROI?") == "10,20,30,40\n" and errors(rig) == []


@pytest.mark.parametrize("line", ["*IDN? 5", "*RST 1", "*CLS 1", "*OPC? 1", "*WAI 0", "SYST:ERR? 1",
                                  "SYSTEM:ERROR:NEXT? 1"])
def test_common_commands_refuse_parameters_with_minus_108(rig, line):
    # IEEE 488.2 section 10: none of these common commands takes a parameter.
    assert ask(rig, "camera", line) == ""
    assert [e.split(",")[0] for e in errors(rig)] == ["-108"]
    assert ask(rig, "lamp", line) == ""
    assert [e.split(",")[0] for e in errors(rig, "lamp")] == ["-108"]


def test_error_texts_are_printable_ascii_and_replies_are_not_lost(rig):
    from drivers.emulator.transports import LineSplitter

    received = b'\xe9XP 1;FOO"\x07 1;*IDN?\n'
    (line,) = LineSplitter().feed(received)
    assert ask(rig, "camera", line) == "GONIO,CCD-512,SN0001,1.0\n"  # the valid query is answered
    # The byte 0xE9 and the BEL are quoted as \xNN, the double quote is doubled (IEEE 488.2
    # 8.7.8), so the string is unambiguous and the reply encodes as ASCII.
    assert errors(rig) == ['-100,"Command error;\'\\xe9XP 1\'"', '-100,"Command error;\'FOO""\\x07 1\'"']


def test_error_description_is_at_most_255_characters(rig):
    ask(rig, "camera", "FOO" + "x" * 3000)
    (entry,) = errors(rig)
    code, description = entry.split(",", 1)
    assert code == "-113" and description.startswith('"Undefined header;FOOxxx') and description.endswith('..."')
    assert len(description) - 2 <= 255  # SCPI-1999 vol. 2, SYSTem:ERRor

"""Emulated lamp supply and lamp model (docs/protocol.md section 3; drivers/emulator/lamp.py)."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.lamp import Lamp, LampParams, relative_output_steady
from drivers.emulator.rig import EmulatedRig


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 1 / np.pi)


@pytest.fixture
def rig():
    return EmulatedRig(lambert, seed=5, motors_on=True)


def ask(rig, line):
    return rig.channels["lamp"].process(line).decode("ascii")


def test_identity_power_on_state_and_settings(rig):
    assert ask(rig, "*IDN?") == "GONIO,LPS-300,SN0001,1.0\n"
    assert ask(rig, "OUTP?;VOLT?;STAT:LAMP?") == "0;120;OK\n"
    assert ask(rig, "MEAS:VOLT?;CURR?") == "0.000;0.0000\n"
    ask(rig, "VOLT 110.5;OUTP ON")
    assert ask(rig, "OUTP?;VOLT?") == "1;110.5\n"
    ask(rig, "outp off;output 1")
    assert ask(rig, "OUTPUT?") == "1\n"
    ask(rig, "*RST")
    assert ask(rig, "OUTP?;VOLT?") == "0;120\n"


def test_bad_settings_are_refused_with_scpi_errors(rig):
    ask(rig, "VOLT 200;OUTP MAYBE;VOLT;LAMP?")
    assert ask(rig, "SYST:ERR?") == '-222,"Data out of range;VOLT must be within 0..132, got 200"\n'
    assert ask(rig, "SYST:ERR?").startswith("-104,")
    assert ask(rig, "SYST:ERR?").startswith("-109,")
    assert ask(rig, "SYST:ERR?").startswith("-113,")
    assert ask(rig, "SYST:ERR?") == '0,"No error"\n'
    assert ask(rig, "VOLT?") == "120\n"  # unchanged


def test_measured_current_inrush_then_hot_filament(rig):
    ask(rig, "OUTP ON")
    inrush = float(ask(rig, "MEAS:CURR?"))
    rig.control.advance(2.0)
    hot = float(ask(rig, "MEAS:CURR?"))
    # Cold filament ~1/14 of the hot resistance: several times the 2.5 A hot current at first.
    assert inrush > 10.0
    # 2 s = 13 filament time constants: 2.5 A within the 0.05 % read-back noise (x5 margin).
    assert hot == pytest.approx(2.5, rel=3e-3)
    ask(rig, "VOLT 108")
    assert float(ask(rig, "MEAS:CURR?")) == pytest.approx(2.5 * 0.9**0.55, rel=3e-3)
    assert float(ask(rig, "MEAS:VOLT?")) == pytest.approx(108.0, rel=3e-3)


def test_output_follows_voltage_power_law_3_4():
    lamp = Lamp(seed=1)
    lamp.switch(True, t=0.0)
    t = 5000.0  # long after warm-up
    full = lamp.output(t)
    lamp.set_voltage(96.0)
    # (96/120)^3.4 = 0.4682: the documented incandescent power law (IES handbook).
    assert lamp.output(t) / full == pytest.approx(0.8**3.4, rel=1e-12)
    assert relative_output_steady(132.0) == pytest.approx(1.1**3.4)


def test_warm_up_rises_to_steady_state():
    params = LampParams()
    lamp = Lamp(params=params, seed=2)
    lamp.switch(True, t=0.0)
    out = np.array([lamp.output(t) for t in (0.0, 0.15, 1.0, 60.0, 1800.0)])
    assert out[0] == 0.0
    assert out[1] == pytest.approx((1 - np.exp(-1)) * 0.98, rel=2e-3)  # one filament time constant
    assert np.all(np.diff(out) > 0)
    # After 15 warm-up time constants the 2 % deficit is gone; drift is below 0.1 %.
    assert out[-1] == pytest.approx(1.0, abs=1.5e-3)


def test_drift_is_slow_and_small_and_flicker_averages_out():
    lamp = Lamp(seed=3)
    lamp.switch(True, t=-1e5)
    values = np.array([lamp.output(t) for t in np.linspace(0, 7200, 200)])
    assert values.max() - values.min() < 2.1e-3  # two 0.05 % sinusoids: peak-to-peak <= 0.2 %
    rng = np.random.default_rng(4)
    short = np.std([lamp.flicker_factor(0.01, rng) for _ in range(4000)])
    long = np.std([lamp.flicker_factor(1.0, rng) for _ in range(4000)])
    # 0.05 % rms for 10 ms; 10x less for 1 s (sqrt(100)); 4000 samples: +-5 % on each.
    assert short == pytest.approx(5e-4, rel=0.1) and long == pytest.approx(5e-5, rel=0.1)


def test_burn_out_fault_darkens_the_sample(rig):
    ask(rig, "OUTP ON")
    rig.control.advance(1000.0)
    rig.control.burn_out_lamp()
    assert ask(rig, "STAT:LAMP?;:MEAS:CURR?") == "FAULT;0.0000\n"
    assert rig.control.true_state().radiance_w_m2_sr == 0.0
    rig.channels["stage"].process("1PA20;1WS")
    rig.channels["camera"].process("EXP 0.05;ROI 206,190,100,100;ACQ")
    mean = float(rig.channels["camera"].process("ROI:STAT?").split(b",")[0])
    assert mean == pytest.approx(100.1, abs=0.1)  # only the dark signal
    rig.control.replace_lamp()
    assert ask(rig, "STAT:LAMP?") == "OK\n"


def test_bad_voltage_in_python_api_names_the_value():
    with pytest.raises(ValueError, match="132"):
        Lamp().set_voltage(150.0)

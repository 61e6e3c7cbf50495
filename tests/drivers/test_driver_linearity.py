"""Camera linearity from a series of exposures, and its correction (drivers/linearity.py).

fit_linearity is checked on synthetic series (the emulator's curve, a curve of the
correction's own form with known coefficients for the error bars, a linear camera), and
acquire_linearity through the Rig against the emulated camera with and without its
non-linearity (drivers.emulator.systematics.nonlinear_signal).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import brentq

from drivers.emulator.ccd import CCDParams
from drivers.emulator.rig import EmulatedRig
from drivers.emulator.systematics import Systematics, nonlinear_signal
from drivers.linearity import (LinearityResult, acquire_linearity, correction_factor, correction_slope, fit_linearity,
                               linearity_error, series_exposures)
from drivers.rig import Rig

K = 0.1            # system gain [DN/e-]
PIXELS = 19044     # a 138 x 138 window
DARK_VAR = 0.72    # temporal dark variance of a pixel [DN^2]
FULL_SCALE = 3995.0
LEVELS, FRAMES = 8, 4


def _series(rng, curve, top=2900.0, lamp_rms=0.0):
    """Frames of a series: the linear signal up to ``top`` DN, bent by ``curve``, with the
    shot and read noise of the window mean and a white lamp noise of ``lamp_rms`` at 10 ms."""
    t = np.repeat(series_exposures(0.03, LEVELS), FRAMES)
    level = np.repeat(np.arange(LEVELS), FRAMES)
    lamp = 1.0 + lamp_rms * np.sqrt(0.01 / t) * rng.standard_normal(t.size)
    linear = top / 0.03 * t * lamp
    noise = np.sqrt((K * linear + DARK_VAR) / PIXELS) * rng.standard_normal(t.size)
    return t, curve(linear + noise), np.ones(t.size), level


def _fit(t, signal, lamp, level):
    return fit_linearity(t, signal, lamp, level, PIXELS, K, np.full(t.size, DARK_VAR))


def test_the_emulators_curve_is_corrected_to_linear():
    rng = np.random.default_rng(1)
    t, signal, lamp, level = _series(rng, lambda s: nonlinear_signal(s, 0.005, FULL_SCALE))
    result = _fit(t, signal, lamp, level)

    def chi2_about_constant(per_exposure):
        means = np.array([per_exposure[level == l].mean() for l in range(LEVELS)])
        z = (means / np.average(means, weights=result.ratio_sigma**-2) - 1.0) / result.ratio_sigma
        return float(np.sum(z**2))

    corrected = signal * correction_factor(signal, result.coefficients, result.signal_range) / t
    # Corrected, the signal per unit exposure is constant within the levels' stated errors:
    # chi-square of 8 level means about their mean below the 99.9 % point of 7 dof (24.3)
    # (the correction's 3 fitted numbers make it smaller still); uncorrected the 0.26 %
    # deficit over the series is hundreds of those errors.
    assert chi2_about_constant(corrected) < 24.3
    assert chi2_about_constant(signal / t) > 1e3
    # the deficit a (S/s_fs)^2 is c2 x^2 with x = S/S_ref: c2 = a (S_ref/s_fs)^2 (3 sigma)
    expected = 0.005 * (result.signal_range / FULL_SCALE) ** 2
    assert abs(result.coefficients[1] - expected) < 3 * np.sqrt(result.covariance[1, 1])
    assert result.dof == LEVELS - 3 and result.frames == FRAMES


def _bent(coefficients, signal_range):
    """The camera whose correction is exactly ``coefficients``: S with S (1 + c.g(S)) = linear."""
    def curve(linear):
        return np.array([brentq(lambda s: s * correction_factor(s, coefficients, signal_range) - y, 0.5 * y, 1.5 * y)
                         for y in linear])
    return curve


def test_the_coefficients_errors_match_their_scatter():
    """Pulls of (c1, c2) over 150 series of a camera with known coefficients, lamp noise
    included (its variance estimated from the frames' scatter)."""
    rng = np.random.default_rng(7)
    truth = np.array([0.0005, 0.003])
    pulls = []
    for _ in range(150):
        t, signal, lamp, level = _series(rng, _bent(truth, 2900.0), lamp_rms=2e-4)
        r = _fit(t, signal, lamp, level)
        # S_ref is the series' top mean, a hair off 2900: the truth in its units
        x = r.signal_range / 2900.0
        pulls.append((r.coefficients - truth * np.array([x, x * x])) / np.sqrt(np.diag(r.covariance)))
    rms = np.sqrt(np.mean(np.square(pulls), axis=0))
    # 150 pulls give the rms to +-6 % (1 sigma); [0.8, 1.2] is 3 sigma
    assert np.all((rms > 0.8) & (rms < 1.2)), rms


def test_a_linear_camera_gets_a_correction_consistent_with_none():
    rng = np.random.default_rng(3)
    chi2 = [_fit(*_series(rng, lambda s: s)).consistency_with_none() for _ in range(60)]
    # chi-square with 2 degrees of freedom: mean 2 (60 draws: +-0.26), 99.9 % below 13.8
    assert 1.4 < np.mean(chi2) < 2.7 and max(chi2) < 13.8


def test_linearity_error_of_the_emulators_curve():
    h = np.linspace(0.0, 1.0, 400)
    signal = FULL_SCALE * h
    # docs/emulator.md: the EMVA 1288 linearity error of s (1 - a (s/s_fs)^2) is 0.37-0.39 a
    assert linearity_error(h, nonlinear_signal(signal, 0.01, FULL_SCALE), FULL_SCALE * 0.99) == pytest.approx(
        0.0037, abs=2e-4)
    assert linearity_error(h, signal, FULL_SCALE) < 1e-12


def test_record_round_trip_and_bad_input():
    rng = np.random.default_rng(5)
    result = _fit(*_series(rng, lambda s: nonlinear_signal(s, 0.005, FULL_SCALE)))
    back = LinearityResult.from_dict(result.to_dict())
    assert np.array_equal(back.coefficients, result.coefficients) and back.signal_range == result.signal_range
    t, signal, lamp, level = _series(rng, lambda s: s)
    with pytest.raises(ValueError, match="at least 4 levels"):
        _fit(t[level < 3], signal[level < 3], lamp[level < 3], level[level < 3])
    with pytest.raises(ValueError, match="one value per frame"):
        fit_linearity(t, signal[:-1], lamp, level, PIXELS, K, np.full(t.size, DARK_VAR))
    with pytest.raises(ValueError, match="positive signal"):
        _fit(t, np.where(level == 0, 0.0, signal), lamp, level)
    with pytest.raises(ValueError, match="at least 4 levels"):
        series_exposures(0.1, 3)


def _lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


@pytest.mark.parametrize("nonlinearity", [0.0, 0.01])
def test_series_through_the_rig_on_the_emulated_camera(nonlinearity):
    with EmulatedRig(_lambert, seed=12, name=f"linearity-{nonlinearity}", lamp_warm=True,
                     systematics=Systematics(nonlinearity=nonlinearity)) as emulator:
        emulator.start(pty=False)
        with Rig.open(emulator.url("stage"), emulator.url("camera"), emulator.url("lamp"), timeout=2.0) as rig:
            rig.lamp_on(120.0)
            start = rig.measure(30.0, 0.0, 0.0, exposure="auto").exposure
            result = acquire_linearity(rig, start, K, lambda t: DARK_VAR + 0.2 * t)
    params = CCDParams()
    # the series climbs to the full well (3000 DN above the offset at gain 1), less the
    # brightest pixel's excursion
    assert 2600.0 < result.signal_range < params.full_well_e * params.base_gain_dn_per_e
    assert result.signal[0] / result.signal_range == pytest.approx(0.05, abs=0.01)
    if nonlinearity:
        expected = nonlinearity * (result.signal_range / (params.max_dn - params.offset_dn)) ** 2
        assert abs(result.coefficients[1] - expected) < 3 * np.sqrt(result.covariance[1, 1])
        assert result.consistency_with_none() > 100.0
    else:
        assert result.consistency_with_none() < 13.8  # chi-square, 2 dof, 99.9 %


class _DriftingLamp:
    """A rig whose lamp jumps by ``jump`` once the top of the series was found: a window of
    PIXELS pixels saturating at 3000 DN, 1.5e5 DN/s at the lamp's first level."""

    def __init__(self, jump: float):
        self.jump, self.calls, self.exposures = jump, 0, []

    def measure(self, exposure: float, dark: str = "auto"):
        from types import SimpleNamespace

        self.calls += 1
        lamp = 1.0 if self.calls <= 6 else self.jump  # the top search takes 6 frames from 10 ms
        signal = 1.5e5 * exposure * lamp
        self.exposures.append(exposure)
        return SimpleNamespace(roi_saturated=int(signal > 3000.0), signal=signal, monitor=float("nan"),
                               roi_pixels=PIXELS, gain=1.0)


def test_a_series_with_a_saturated_frame_is_measured_again_from_a_lower_top():
    rig = _DriftingLamp(1.15)  # the top found, 2624 DN, now reads 3017 DN: saturated
    result = acquire_linearity(rig, 0.01, K, lambda t: DARK_VAR)
    top = 0.01 * 1.15**4
    assert max(rig.exposures[6:]) == pytest.approx(top)  # the first series reached the top found
    assert result.exposures.max() == pytest.approx(top / 1.15, rel=1e-6)
    assert result.signal_range < 3000.0 and np.all(np.asarray(result.series["signal"]) <= 3000.0)
    with pytest.raises(ValueError, match="saturated at every top exposure"):
        acquire_linearity(_DriftingLamp(2.0), 0.01, K, lambda t: DARK_VAR)  # 3 steps down still saturate


def test_the_record_keeps_every_frame_and_fits_again_from_them():
    rng = np.random.default_rng(5)
    result = _fit(*_series(rng, lambda s: nonlinear_signal(s, 0.005, FULL_SCALE), lamp_rms=2e-4))
    back = LinearityResult.from_dict(json.loads(json.dumps(result.to_dict())))
    assert len(back.series["signal"]) == LEVELS * FRAMES
    again = back.refit()
    np.testing.assert_array_equal(again.coefficients, result.coefficients)
    np.testing.assert_array_equal(again.covariance, result.covariance)


def test_a_lamp_drift_between_the_passes_does_not_inflate_the_lamp_term():
    """A lamp drifting linearly by 0.1 % over the series (up, then down: it cancels in each
    level's mean) leaves the lamp term as without drift: the scatter is taken within each
    pass's frames of a level, not across the passes."""
    exposures = series_exposures(0.03, LEVELS)
    order = np.repeat(np.r_[np.arange(LEVELS), np.arange(LEVELS)[::-1]], 2)

    def series(drift: float):
        rng = np.random.default_rng(11)
        t = exposures[order]
        lamp = (1.0 + drift * np.linspace(0.0, 1.0, t.size)) * (1.0 + 2e-4 * np.sqrt(0.01 / t)
                                                                 * rng.standard_normal(t.size))
        linear = 2900.0 / 0.03 * t * lamp
        signal = linear + np.sqrt((K * linear + DARK_VAR) / PIXELS) * rng.standard_normal(t.size)
        return _fit(t, signal, np.ones(t.size), order)

    steady, drifting = series(0.0), series(1e-3)
    # The same noise draws: the drift adds to consecutive frames' differences at most
    # 1e-3 / 31 per frame, (3e-5)^2 t ~ 1e-11 s against q = (2e-4)^2 x 0.01 s = 4e-10 s;
    # pooled across the passes it would add (5e-4)^2 t ~ 4e-9 s, ten times q.
    assert drifting.lamp_variance == pytest.approx(steady.lamp_variance, rel=0.1)
    assert steady.lamp_variance == pytest.approx(4e-10, rel=0.5)  # 15 dof of scatter: +-40 % (1 sigma)


def test_an_error_of_the_signal_scales_by_the_corrections_slope():
    """The noise of a corrected signal, by Monte Carlo of the correction itself: its slope
    1 + 2 c1 x + 3 c2 x^2, not its factor 1 + c1 x + c2 x^2 (here 1.15 against 1.05)."""
    rng = np.random.default_rng(2)
    coefficients, top = [0.0, 0.05], 3000.0
    signal = 3000.0 + 5.0 * rng.standard_normal(200_000)
    corrected = signal * correction_factor(signal, coefficients, top)
    # 2e5 draws: the standard deviation to 0.16 % (1 sigma); 0.5 % is 3 of them, and 7 % off
    # is the factor
    assert np.std(corrected) / 5.0 == pytest.approx(float(correction_slope(3000.0, coefficients, top)), rel=5e-3)
    assert float(correction_slope(3000.0, coefficients, top)) == pytest.approx(1.15, rel=1e-12)

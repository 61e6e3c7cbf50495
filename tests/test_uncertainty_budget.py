"""The uncertainty budget of a reduced recording (gonio.reduction, gonio.uncertainty).

Each noise source of the emulated rig is switched on alone (everything else at its quiet
setting) and must show up in its own budget component, at the size the emulator's
constants give and at the size of the scatter it causes (GUM, JCGM 100:2008, 4.2-4.3).
The reference standard must be reduced like the sample, low signals kept, and the
calibration prior's width must come from the budget.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.emulator.ccd import CCDParams
from drivers.emulator.lamp import LampParams
from drivers.emulator.monitor import MonitorParams
from drivers.emulator.stage_firmware import DEFAULT_AXES
from gonio import acquisition, data, protocols, reduction
from gonio.cli.run import emulated_rig
from gonio.instrument import aperture_averaged

#: A lamp without flicker or drift (its warm-up is waited out by the run).
STEADY = LampParams(flicker_rms=0.0, drift_amplitude=0.0)
#: A monitor without reading noise.
SILENT_MONITOR = MonitorParams(noise_10ms_v=0.0)

REPEATED = """
[protocol]
name = "repeats"
[sample]
label = "plaster"
{extra}
[[block]]
name = "bright"
theta_i = 30
view = [-20, 20]
repeats = 40
"""


def _run(tmp_path, text, sample="oren-nayar:sigma=30,rho=0.9", seed=0, name="budget", **options):
    protocol = protocols.loads(text, source="budget.toml")
    folder = tmp_path / name
    reflectance = protocol.reference.reflectance if protocol.reference else None
    with emulated_rig(sample, seed, name=f"{name}-{seed}", **{"realism": "ideal", **options}) as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                 change_sample=lambda which: change(which, reflectance))
    return folder


def _relative(reduced, name):
    return reduced.budget[name] / np.abs(reduced.radiance)


def _ratios(reduced):
    return [s["observed_std"] / s["stated_std"] for s in reduced.repeat_statistics]


# ----------------------------------------------------------------------------- one source at a time
def test_monitor_noise_alone_is_the_lamp_monitor_term_and_its_scatter(tmp_path):
    """A monitor 10 times noisier than the default (3e-4 V per 10 ms), steady lamp, ideal
    CCD patterns: the lamp_monitor term is noise / reading and the repeats scatter by it.
    40 repeats estimate a standard deviation to 11 % (1 / sqrt(2 * 39)): 0.65..1.35 is 3 sigma."""
    folder = _run(tmp_path, REPEATED.format(extra=""), lamp_params=STEADY, fixed_pattern=False,
                  monitor_params=MonitorParams(noise_10ms_v=3e-4))
    reduced = reduction.reduce_recording(folder, lamp="monitor")
    points = data.read_points(folder)
    t = points["exposure"][points["status"] == "ok"][0]
    expected = 3e-4 * math.sqrt(0.01 / t) / 1.0  # V per V of a warm lamp at rated voltage
    per_reading = reduced.budget["lamp_monitor"] * np.sqrt(reduced.repeats) / np.abs(reduced.radiance)
    # the dark characterisation measures the noise to ~18 % (16 readings at two times): 2.5 sigma
    np.testing.assert_allclose(per_reading, expected, rtol=0.45)
    assert np.all(per_reading > 2 * reduced.budget["shot_read"] * np.sqrt(reduced.repeats) / reduced.radiance)
    assert all(0.65 < r < 1.35 for r in _ratios(reduced)), _ratios(reduced)
    assert np.all(_relative(reduced, "prnu") == 0.0)  # fixed patterns off


def test_flicker_alone_is_measured_by_the_checks_and_scales_with_the_exposure(tmp_path):
    """No monitor, flicker 2e-3 per 10 ms (4 times the default), no drift: the checks' frames
    measure the flicker at their exposure; the term at the sample's exposure scales as
    1/sqrt(t) and matches the repeats' scatter."""
    extra = "[checks]\nevery = 10\nframes = 6\ngeometry = [45, 0, -10]\n"
    folder = _run(tmp_path, REPEATED.format(extra=extra), monitor=False, fixed_pattern=False,
                  lamp_params=LampParams(flicker_rms=2e-3, drift_amplitude=0.0))
    reduced = reduction.reduce_recording(folder)
    assert reduced.unit.startswith("DN/s (lamp drift corrected")
    points = data.read_points(folder)
    check_t = points["exposure"][points["block"] == acquisition.CHECK_BLOCK][0]
    truth_at_check = 2e-3 * math.sqrt(0.01 / check_t)
    # 7 checks x 5 dof = 35 dof: the flicker's standard deviation to 12 %; 3 sigma
    assert reduced.consistency["flicker_relative_at_check_exposure"] == pytest.approx(truth_at_check, rel=0.36)
    bright = points["block"] == "bright"
    sample_t = np.array([points["exposure"][bright & (points["view"] == v)][0] for v in (-20.0, 20.0)])
    single = reduced.budget["lamp_flicker"] * np.sqrt(reduced.repeats) / np.abs(reduced.radiance)
    np.testing.assert_allclose(single[np.argsort(reduced.view)], reduced.consistency[
        "flicker_relative_at_check_exposure"] * np.sqrt(check_t / sample_t), rtol=1e-3)  # |mean| vs mean |x|
    assert all(0.6 < r < 1.4 for r in _ratios(reduced)), _ratios(reduced)


def test_drift_alone_is_corrected_by_the_checks_and_stated_in_the_drift_term(tmp_path):
    """A lamp drifting by 1 % with a 120 s period, no flicker, no monitor: the raw signal
    of 40 repeats wanders by ~3e-3 (far beyond the CCD noise); after the checks'
    correction (every 2 points, ~5 s apart) it scatters by what the budget states (CCD,
    the checks' noise and the interpolation's miss that the checks reveal)."""
    extra = "[checks]\nevery = 2\nframes = 4\ngeometry = [30, 0, -15]\n"
    params = LampParams(flicker_rms=0.0, drift_amplitude=5e-3, drift_periods_s=(120.0, 3700.0))
    text = REPEATED.format(extra=extra).replace("view = [-20, 20]", "view = [-20, -10]")
    folder = _run(tmp_path, text, monitor=False, fixed_pattern=False, lamp_params=params)
    points = data.read_points(folder)
    raw = points["signal_rate"][(points["block"] == "bright") & (points["view"] == -20.0)]
    assert np.std(raw) / np.mean(raw) > 5e-4
    reduced = reduction.reduce_recording(folder)
    assert np.all(reduced.budget["lamp_drift"] > 0) and "lamp_flicker" in reduced.budget
    corrected = [s["observed_std"] / np.mean(reduced.radiance) for s in reduced.repeat_statistics]
    assert max(corrected) < 0.2 * np.std(raw) / np.mean(raw)
    assert all(0.6 < r < 1.4 for r in _ratios(reduced)), _ratios(reduced)


def test_prnu_alone_is_the_prnu_term_and_matches_the_sensor_pattern(tmp_path):
    """PRNU 2 % (four times the default) with a steady lamp and a silent monitor: the prnu
    term of each value is p sqrt(1/N - 1/N_max), the spread of the true window means of the
    emulated sensor's response map about the largest window; the camera characterisation
    measures p itself."""
    text = """
[protocol]
name = "windows"
[sample]
label = "matte"
[exposure]
mode = "fixed"
time = 0.05
[[block]]
theta_i = 20
view = [-80, -70, -60, -45, -30, 0, 45, 60, 70, 80]
"""
    params = CCDParams(prnu_rel=0.02)
    protocol = protocols.loads(text, source="windows.toml")
    with emulated_rig("lambert:rho=0.5", 3, name="prnu", realism="ideal", ccd_params=params, lamp_params=STEADY,
                      monitor_params=SILENT_MONITOR) as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, tmp_path / "prnu", metadata=meta, clock=emulator.control.now)
        response = emulator.sensor.response_map
        rois = {v: rig.roi_for_view(v) for v in (-80, -70, -60, -45, -30, 0, 45, 60, 70, 80)}
    meta = data.read_metadata(tmp_path / "prnu")
    assert meta["camera"]["prnu"] == pytest.approx(0.02, rel=0.1)  # 138 x 138 pixels: ~2 % statistical
    reduced = reduction.reduce_recording(tmp_path / "prnu")
    window_mean = {v: response[r.slices()].mean() for v, r in rois.items()}
    largest = window_mean[0]
    true_offsets = np.array([window_mean[v] / largest - 1 for v in sorted(rois)])
    stated = _relative(reduced, "prnu")[np.argsort(reduced.view)]
    assert stated[sorted(rois).index(0)] == 0.0  # the largest window is the reference
    # 9 windows: their rms offset estimates the rms stated size to ~25 %; 0.5..1.6 covers it
    others = [k for k, v in enumerate(sorted(rois)) if v != 0]
    ratio = np.sqrt(np.mean(true_offsets[others] ** 2)) / np.sqrt(np.mean(stated[others] ** 2))
    assert 0.5 < ratio < 1.6, (ratio, true_offsets, stated)


def test_read_noise_alone_shows_in_the_dark_and_shot_read_terms(tmp_path):
    """Read noise 10 times the default (80 e-, i.e. 8 DN): the dark term is
    sqrt(sigma_d^2(t)) / sqrt(N) with sigma_d ~ 8 DN, measured by the characterisation."""
    folder = _run(tmp_path, REPEATED.format(extra=""), ccd_params=CCDParams(read_noise_e=80.0),
                  lamp_params=STEADY, fixed_pattern=False, monitor_params=SILENT_MONITOR)
    meta = data.read_metadata(folder)
    assert math.sqrt(meta["camera"]["dark_variance_dn2"]) == pytest.approx(8.0, rel=0.05)
    reduced = reduction.reduce_recording(folder)
    points = data.read_points(folder)
    for k, view in enumerate(reduced.view):
        ok = (points["status"] == "ok") & (points["view"] == round(view))
        n, t = points["roi_pixels"][ok][0], points["exposure"][ok][0]
        monitor = np.mean(points["monitor"][ok]) - meta["monitor_dark"]["offset_v"]
        # a fresh dark frame every 20 points (darks.every), reused in between: the 40 repeats
        # of a view share 1 to 4 dark frames, whose noise is 8 DN / sqrt(N) / t per V each
        per_dark = 8.0 / math.sqrt(n) / t / monitor
        assert per_dark / math.sqrt(4) * 0.99 < reduced.budget["dark"][k] < per_dark * 1.01
    assert all(0.65 < r < 1.35 for r in _ratios(reduced)), _ratios(reduced)


def test_coarse_encoder_alone_is_the_angle_term(tmp_path):
    """An encoder of 0.05 deg steps (50 times the default): the readback is known to
    0.05 / sqrt(12) deg, and near grazing incidence (theta_i = 80, where d ln L / d theta_i
    = -tan 80 per rad = -0.099 per deg) that is the largest term."""
    axes = tuple(type(a)(**{**a.__dict__, "resolution": 0.05}) for a in DEFAULT_AXES)
    text = REPEATED.format(extra="").replace("theta_i = 30", "theta_i = 80").replace("repeats = 40", "repeats = 3")
    folder = _run(tmp_path, text, sample="lambert:rho=0.5", axes=axes, lamp_params=STEADY, fixed_pattern=False,
                  monitor_params=SILENT_MONITOR)
    reduced = reduction.reduce_recording(folder)
    expected = math.tan(math.radians(80)) * math.radians(1) * 0.05 / math.sqrt(12)  # per reading, lamp axis
    # the sweep alternates between the two views, so each of the three readings of a view
    # is a new stage arrival with its own quantisation error: the mean's term is 1/sqrt(3)
    np.testing.assert_allclose(_relative(reduced, "angle"), expected / math.sqrt(3), rtol=0.02)
    largest = max(reduced.budget, key=lambda k: float(np.mean(reduced.budget[k])))
    assert largest == "angle"


def test_the_certificate_and_angular_behaviour_of_the_standard_enter_the_calibration(tmp_path):
    text = """
[protocol]
name = "calibrated"
[sample]
label = "matte"
[reference]
label = "diffuse standard"
reflectance = 0.99
reflectance_uncertainty = 0.005
angular_uncertainty = 0.002
geometries = [[30, 0, -10], [45, 0, -10]]
[[block]]
theta_i = 30
view = [-40, 0, 40]
"""
    folder = _run(tmp_path, text, sample="lambert:rho=0.5")
    reduced = reduction.reduce_recording(folder)
    assert reduced.calibration["certificate"] == 0.005 and reduced.calibration["angular behaviour"] == 0.002
    total = math.sqrt(sum(v**2 for v in reduced.calibration.values()))
    assert reduced.reference_irradiance_sigma == pytest.approx(total * reduced.reference_irradiance, rel=1e-12)
    _, priors = reduced.fit_inputs()
    assert priors["scale"].sd == pytest.approx(reduced.reference_irradiance_sigma, rel=1e-12)


# ----------------------------------------------------------------------------- the whole budget
def test_the_reference_is_reduced_like_the_sample_and_rho_comes_out_unbiased(tmp_path):
    """A Lambertian sample (rho = 0.5) measured with a 0.99 standard: the absolute BRDF
    equals the aperture-averaged Lambertian BRDF the fit uses within the stated
    uncertainty. Skipping the aperture average for the standard biased rho by +2.4e-4,
    several times the ~5e-5 this test resolves."""
    text = """
[protocol]
name = "absolute"
[sample]
label = "matte"
[reference]
label = "diffuse standard"
reflectance = 0.99
geometries = [[30, 0, -10], [45, 0, -10], [60, 0, -10]]
[[block]]
theta_i = [30, 60]
view = [-70, -50, -30, 0, 15, 45, 70]
"""
    folder = _run(tmp_path, text, sample="lambert:rho=0.5")
    reduced = reduction.reduce_recording(folder)
    brdf = reduced.brdf()
    model = aperture_averaged("lambert", *reduced.metadata["aperture_sr"])
    expected = model(brdf.theta_i, brdf.phi_i, brdf.theta_r, brdf.phi_r, rho=0.5)
    residual = brdf.value / expected - 1
    # the calibration is common to every value: compare the mean with it and the mean noise
    cal = reduced.reference_irradiance_sigma / reduced.reference_irradiance
    noise = np.sqrt(np.sum((reduced.radiance_sigma / reduced.radiance) ** 2)) / len(residual)
    assert abs(residual.mean()) < 3 * math.hypot(cal, noise), (residual.mean(), cal, noise)
    assert math.hypot(cal, noise) < 1e-4  # the test resolves the old +2.4e-4 bias


def test_low_signal_points_are_kept_flagged_and_unbiased(tmp_path):
    """A black sample (rho = 0) at a fixed exposure: the dark-subtracted signal is noise
    about zero, positive and negative; every point is kept with its uncertainty (dropping
    the negative ones biased low-light data upwards), flagged low_signal, and their mean
    is zero within its uncertainty."""
    text = REPEATED.format(extra="[exposure]\nmode = 'fixed'\ntime = 0.2\n").replace("repeats = 40", "repeats = 12")
    folder = _run(tmp_path, text, sample="lambert:rho=0.0", monitor_params=SILENT_MONITOR)
    points = data.read_points(folder)
    ok = (points["status"] == "ok") & (points["block"] == "bright")
    assert ok.sum() == 24 and all("low_signal" in f for f in points["flags"][ok])
    readings = reduction.read_readings(folder)
    values = readings.value[readings.index][readings.column("block") == "bright"]
    assert (values < 0).any() and (values > 0).any()
    reduced = reduction.reduce_recording(folder)
    assert list(reduced.flags) == ["low_signal", "low_signal"]
    assert np.all(np.isfinite(reduced.radiance_sigma)) and np.all(reduced.radiance_sigma > 0)
    assert abs(np.mean(reduced.radiance)) < 3 * np.sqrt(np.sum(reduced.radiance_sigma**2)) / 2


def test_budget_components_add_up_and_the_table_names_them(tmp_path):
    folder = _run(tmp_path, REPEATED.format(extra=""))
    reduced = reduction.reduce_recording(folder)
    total = np.sqrt(sum(c**2 for c in reduced.budget.values()))
    np.testing.assert_allclose(total, reduced.radiance_sigma, rtol=1e-12)
    table = reduced.budget_table()
    for name in ("shot_read", "dark", "prnu", "lamp_monitor", "angle"):
        assert name in table
    assert set(reduced.budget_summary()["components"]) == set(reduced.budget)


def test_gonio_reduce_prints_the_budget_and_writes_csv_and_json(tmp_path, capsys):
    import json

    from gonio.cli import main

    folder = _run(tmp_path, REPEATED.format(extra=""))
    out = tmp_path / "reduced"
    assert main(["reduce", str(folder), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "uncertainty budget" in printed and "lamp_monitor" in printed
    header = (out / "reduced.csv").read_text().splitlines()[0].split(",")
    assert header[:7] == ["theta_i", "phi_i", "theta_r", "phi_r", "view", "value", "sigma"]
    assert "u_shot_read" in header and "u_lamp_monitor" in header
    budget = json.loads((out / "budget.json").read_text())
    assert budget["unit"] == "DN/s per V of lamp monitor" and len(budget["repeat_statistics"]) == 2
    # a second run needs --overwrite; a folder with someone else's reduced.csv is refused
    assert main(["reduce", str(folder), "--out", str(out)]) == 2
    assert main(["reduce", str(folder), "--out", str(out), "--overwrite"]) == 0
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "reduced.csv").write_text("mine\n")
    assert main(["reduce", str(folder), "--out", str(foreign), "--overwrite"]) == 2
    assert (foreign / "reduced.csv").read_text() == "mine\n"
    # a budget.json that merely claims the format, or lists another table, is not trusted:
    # --overwrite replaces only a whole reduction gonio wrote (its manifest)
    (foreign / "budget.json").write_text(json.dumps({"format": "gonio reduction 1"}))
    assert main(["reduce", str(folder), "--out", str(foreign), "--overwrite"]) == 2
    assert (foreign / "reduced.csv").read_text() == "mine\n"
    (out / "reduced.csv").write_text((out / "reduced.csv").read_text() + "edited by hand\n")
    assert main(["reduce", str(folder), "--out", str(out), "--overwrite"]) == 2
    assert "not one reduction" in capsys.readouterr().err


def test_without_monitor_checks_or_repeats_the_budget_says_the_lamp_was_not_measured(tmp_path):
    text = REPEATED.format(extra="").replace("repeats = 40", "repeats = 1")
    folder = _run(tmp_path, text, monitor=False)
    reduced = reduction.reduce_recording(folder)
    assert any("not measured" in w for w in reduced.warnings)
    assert "lamp_flicker" not in reduced.budget
    dataset = reduced.normalised_radiance() if False else reduced.relative_radiance()
    assert any("not measured" in w for w in dataset.metadata["reduction_warnings"])

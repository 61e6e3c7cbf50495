"""Remedies for the emulated rig's camera non-linearity and lamp beam non-uniformity.

The camera's linearity series (drivers/linearity.py, measured by gonio.acquisition with
the photon transfer) corrects every reading in the reduction, its uncertainty a
covariance between values (gonio.uncertainty.LinearityCorrection); the reference standard
read at each lamp polar angle calibrates that angle's irradiance (Reduced.fit_inputs
(calibration="per-incidence")). Both are tested on recordings of the emulated rig with
the systematic switched on (docs/emulator.md, "Systematic errors"), against the truth of
the emulated sample and against the ideal rig.
"""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from gonio import acquisition
from gonio.cli import main
from gonio.fitting import FitProblem, fit
from gonio.fitting.rig_errors import RigPrediction, incidence_weights
from tests.emulated_recording import STANDARD_ANGLES, record

PROTOCOL = """
[protocol]
name = "remedies-test"
[sample]
label = "plaster"
[[block]]
theta_i = [30, 45, 60]
phi_i = 0
view = { start = -70, stop = 70, step = 10 }
[reference]
label = "standard"
reflectance = 0.99
geometries = [[30, 0, -10], [45, 0, -10], [60, 0, -10]]
"""
SAMPLE = "oren-nayar:sigma=30,rho=0.9,ir_weight=1"
TRUTH = {"sigma": 30.0, "rho": 0.9}
FIXED = {"ir_weight": 1.0}


def _record(folder, realism: str, text: str = PROTOCOL):
    return record(folder, text, SAMPLE, 4, realism)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The ideal rig, the camera's non-linearity (lab: 0.5 % at full scale), the lamp beam's
    non-uniformity (lab: 2 % at the sample's edge)."""
    root = tmp_path_factory.mktemp("remedies")
    return {name: _record(root / name, realism) for name, realism in
            (("ideal", "ideal"), ("nonlinear", "ideal:nonlinearity=0.005"), ("beam", "ideal:beam_falloff=0.02"))}


def _least_squares(dataset, priors, **options):
    return fit(dataset, "oren-nayar", FIXED, priors=priors, mcmc=False, **options)


def _within(result, k: float = 3.0) -> bool:
    """Whether sigma and rho lie within k standard errors of the truth (k = 3: a fixed seed)."""
    ls = result.least_squares
    return all(abs(ls.values[n] - t) < k * ls.stderr[n] for n, t in TRUTH.items())


# ----------------------------------------------------------------------- linearity
def test_corrected_readings_fit_as_the_linear_cameras_do(recordings):
    raw = acquisition.reduce_recording(recordings["nonlinear"], linearity=False)
    corrected = acquisition.reduce_recording(recordings["nonlinear"])
    fits = {name: _least_squares(*r.fit_inputs()) for name, r in
            (("raw", raw), ("corrected", corrected), ("ideal", acquisition.reduce_recording(recordings["ideal"])))}
    ideal = fits["ideal"].least_squares
    # Uncorrected, values read at different fractions of full scale scatter by the curve
    # (reduced chi-square 3.7-4.8 here over four seeds, 0.7-1.4 on the ideal rig): flagged.
    assert fits["raw"].adequate is False and fits["raw"].least_squares.redchi > 2 * ideal.redchi
    # Corrected, the same seed's fit is the linear camera's: measured over four seeds,
    # reduced chi-square within 0.01 and sigma, rho within 0.1 standard errors of the ideal
    # rig's (the same noise draws where the automatic exposure chose the same frames).
    ls = fits["corrected"].least_squares
    assert fits["corrected"].adequate is True and ls.redchi == pytest.approx(ideal.redchi, rel=0.1)
    for name in TRUTH:
        assert abs(ls.values[name] - ideal.values[name]) < 0.3 * ideal.stderr[name]
        assert ls.stderr[name] == pytest.approx(ideal.stderr[name], rel=0.05)
    assert any("left out on request" in w for w in raw.warnings)


def test_the_series_is_recorded_and_its_uncertainty_is_a_covariance(recordings):
    camera = json.loads((recordings["nonlinear"] / "metadata.json").read_text())["camera"]
    series = camera["linearity"]
    c2, sd = series["coefficients"][1], np.sqrt(series["covariance"][1][1])
    assert abs(c2 - 0.005 * (series["signal_range_dn"] / 3995.0) ** 2) < 3 * sd  # the emulator's curve
    reduced = acquisition.reduce_recording(recordings["nonlinear"])
    assert reduced.linearity_jacobian.shape == (len(reduced.radiance), 2)
    linear = reduced.budget["linearity"]
    # the component is |x| sqrt(d C d^T) of the recorded series (d relative to E_0's)
    d = reduced.linearity_jacobian - reduced.reference_linearity
    expected = np.abs(reduced.radiance) * np.sqrt(np.einsum("ni,ij,nj->n", d, np.array(series["covariance"]), d))
    np.testing.assert_allclose(linear, expected, rtol=1e-12)
    assert np.all(linear > 0)
    covariance = reduced.covariance()
    np.testing.assert_allclose(np.sqrt(np.diag(covariance)), reduced.radiance_sigma, rtol=1e-12)
    assert np.linalg.eigvalsh(covariance).min() > 0
    # the correction's part is fully correlated: values share it off the diagonal
    without = acquisition.reduce_recording(recordings["nonlinear"], linearity=False).covariance()
    assert not np.allclose(covariance - np.diag(np.diag(covariance)), without - np.diag(np.diag(without)))


def test_the_readings_noise_is_scaled_by_the_corrections_slope(recordings):
    from gonio.data import read_metadata, read_points
    from gonio.reduction.readings import readings_of

    meta, points = read_metadata(recordings["nonlinear"]), read_points(recordings["nonlinear"])
    corrected, raw = readings_of(meta, points), readings_of(meta, points, linearity=False)
    signal = (points["roi_mean"] - points["dark_mean"])[corrected.index]
    slope = corrected.linearity.slope(signal)
    factor = corrected.linearity.factor(signal)
    assert np.max(slope - factor) > 1e-3  # the readings near the top: c2 x^2 ~ 2e-3 apart
    for name in ("shot_read", "dark", "prnu"):
        np.testing.assert_allclose(corrected.budget[name][corrected.index], raw.budget[name][raw.index] * slope,
                                   rtol=1e-12)


def test_a_linear_camera_gets_no_correction_to_speak_of(recordings):
    series = json.loads((recordings["ideal"] / "metadata.json").read_text())["camera"]["linearity"]
    c, covariance = np.array(series["coefficients"]), np.array(series["covariance"])
    assert c @ np.linalg.solve(covariance, c) < 13.8  # chi-square, 2 dof, 99.9 %
    corrected = acquisition.reduce_recording(recordings["ideal"])
    raw = acquisition.reduce_recording(recordings["ideal"], linearity=False)
    # the correction moves no value by more than its own uncertainty would allow (3 sigma)
    shift = np.abs(corrected.radiance / raw.radiance - 1.0)
    assert np.all(shift < 3 * corrected.radiance_sigma / corrected.radiance)


def test_a_recording_without_a_series_says_it_is_not_corrected(recordings, tmp_path):
    old = shutil.copytree(recordings["ideal"], tmp_path / "old")
    meta = json.loads((old / "metadata.json").read_text())
    del meta["camera"]["linearity"]
    (old / "metadata.json").write_text(json.dumps(meta))
    reduced = acquisition.reduce_recording(old)
    assert reduced.linearity_jacobian is None and "linearity" not in reduced.budget
    assert any("not corrected for the camera's non-linearity" in w for w in reduced.warnings)


def test_a_series_record_that_cannot_be_read_is_reported_as_such(recordings, tmp_path):
    broken = shutil.copytree(recordings["ideal"], tmp_path / "broken")
    meta = json.loads((broken / "metadata.json").read_text())
    del meta["camera"]["linearity"]["covariance"]
    (broken / "metadata.json").write_text(json.dumps(meta))
    reduced = acquisition.reduce_recording(broken)
    assert reduced.linearity_jacobian is None
    assert any("camera.linearity cannot be read (KeyError: no 'covariance')" in w for w in reduced.warnings)
    assert not any("has no linearity series" in w for w in reduced.warnings)


SHORT = """
[protocol]
name = "short"
[sample]
label = "plaster"
[[block]]
theta_i = 30
phi_i = 0
view = [0, 20, -40]
"""


@pytest.mark.parametrize("stored", [None, {"error": "linearity series failed (LampError: lamp current is 0 A)"}])
def test_a_resume_with_no_point_left_measures_a_missing_or_failed_series(tmp_path, stored):
    """The series comes after the last point: a run interrupted during it, resumed, has no
    point left and did not switch the lamp on for one; the resume measures the series (a
    failed one again), and the readings are corrected."""
    folder = record(tmp_path / "short", SHORT, SAMPLE, 4)
    meta = json.loads((folder / "metadata.json").read_text())
    measured = meta["camera"].pop("linearity")
    if stored is not None:
        meta["camera"]["linearity"] = stored
    (folder / "metadata.json").write_text(json.dumps(meta))
    record(folder, SHORT, SAMPLE, 4, resume=True)
    series = json.loads((folder / "metadata.json").read_text())["camera"]["linearity"]
    assert "error" not in series, series
    # the same seed, the emulator's lamp started again: a series of the same camera, its
    # coefficients within 4 of their standard errors of the first run's
    difference = np.subtract(series["coefficients"], measured["coefficients"])
    assert np.all(np.abs(difference) < 4 * np.sqrt(np.diag(measured["covariance"])))
    assert acquisition.reduce_recording(folder).linearity_jacobian is not None


class _FailingRig:
    """A rig whose first exposure raises ``error``."""

    def __init__(self, error: Exception):
        self.error = error

    def measure(self, *args, **kwargs):
        raise self.error


def test_a_series_records_an_instrument_failure_and_raises_a_fault_of_the_program():
    from drivers.errors import CameraError
    from gonio.protocols import loads

    camera = {"geometry": [30.0, 0.0, 10.0], "system_gain_dn_per_e": 0.1, "dark_variance_dn2": 1.0,
              "dark_variance_rate_dn2_per_s": 0.0, "exposures_s": [0.01]}
    protocol = loads(SHORT, source="short.toml")
    failed = acquisition.characterise_linearity(_FailingRig(CameraError(-300, "camera fault")), camera, protocol)
    assert failed == {"error": "linearity series failed (CameraError: camera error -300: camera fault)"}
    with pytest.raises(TypeError, match="a bug"):
        acquisition.characterise_linearity(_FailingRig(TypeError("a bug")), camera, protocol)


# ----------------------------------------------------------------------- beam profile
def test_calibration_per_incidence_removes_the_beams_bias_at_the_ideal_error(recordings):
    beam = acquisition.reduce_recording(recordings["beam"])
    ideal = acquisition.reduce_recording(recordings["ideal"])
    common = _least_squares(*beam.fit_inputs())
    per_incidence = _least_squares(*beam.fit_inputs("per-incidence"))
    reference = _least_squares(*ideal.fit_inputs())
    # One E_0 for every incidence: each incidence's level is off by the beam's own factor
    # (8e-4 between 30 and 60 deg, 10 times the values' errors), and the fit says so.
    assert common.adequate is False or not _within(common)
    assert per_incidence.adequate is True and _within(per_incidence)
    for name in TRUTH:  # at the error of the ideal rig's common calibration (measured 1.0-1.1)
        assert per_incidence.least_squares.stderr[name] < 1.3 * reference.least_squares.stderr[name]
    assert any("differs between lamp polar angles" in w for w in beam.warnings)
    assert not any("differs between lamp polar angles" in w for w in ideal.warnings)
    dataset, _ = beam.fit_inputs("per-incidence")
    assert dataset.metadata["calibration"] == "per-incidence"
    assert not any("differs between" in w for w in dataset.metadata.get("reduction_warnings", []))


def test_per_incidence_datasets_divide_by_each_incidences_irradiance(recordings):
    beam = acquisition.reduce_recording(recordings["beam"])
    irradiance = np.array([c.irradiance for c in beam.incidences])[beam.incidence]
    relative, _ = beam.fit_inputs("per-incidence")
    np.testing.assert_allclose(relative.value, beam.radiance * beam.reference_irradiance / irradiance, rtol=1e-14)
    brdf = beam.brdf("per-incidence")
    np.testing.assert_allclose(brdf.value, beam.radiance / (irradiance * np.cos(np.radians(beam.theta_i))), rtol=1e-14)
    for dataset in (relative, brdf):
        assert np.linalg.eigvalsh(dataset.covariance).min() > 0
    # values of one incidence share their irradiance's error; of two, only its part in E_0
    one = np.flatnonzero(beam.incidence == 0)[:2]
    two = [one[0], np.flatnonzero(beam.incidence == 1)[0]]
    correlation = relative.covariance / np.outer(relative.sigma, relative.sigma)
    assert correlation[one[0], one[1]] > correlation[two[0], two[1]] + 0.05


def test_the_standards_departure_from_lambertian_is_an_error_of_each_angle(recordings):
    """Calibrated per incidence, each E_k carries the standard's departure from Lambertian
    at its own angle: an error shared by that angle's values, not by all (it would have
    the shape of a beam's falloff); the certificate stays common to all."""
    from dataclasses import replace

    beam = acquisition.reduce_recording(recordings["beam"])
    a, certificate = 1e-3, 2e-3
    lambertian = replace(beam, calibration={**beam.calibration, "certificate": certificate, "angular behaviour": 0.0})
    departing = replace(lambertian, calibration={**lambertian.calibration, "angular behaviour": a})
    same = np.flatnonzero(beam.incidence == 0)[:2]
    other = [same[0], np.flatnonzero(beam.incidence == 2)[0]]

    def added(method, pair):
        """What the departure adds to the relative covariance of a pair of values."""
        datasets = [getattr(r, method)(calibration="per-incidence") for r in (departing, lambertian)]
        i, j = pair
        return (datasets[0].covariance[i, j] - datasets[1].covariance[i, j]) / (datasets[0].value[i]
                                                                              * datasets[0].value[j])

    # rel 1e-6: the differences are of covariances ~5e-6 relative, rounded to ~1e-21
    assert added("brdf", same) == pytest.approx(a**2, rel=1e-6)
    assert abs(added("brdf", other)) < 1e-6 * a**2
    w = np.array([c.weight for c in beam.incidences])
    w = w / w.sum()
    assert added("relative_radiance", same) == pytest.approx(a**2 * (1 - 2 * w[0] + np.sum(w**2)), rel=1e-6)
    assert added("relative_radiance", other) == pytest.approx(a**2 * (np.sum(w**2) - w[0] - w[2]), rel=1e-6)


def test_a_sample_incidence_without_a_reference_is_refused(tmp_path):
    text = PROTOCOL.replace("geometries = [[30, 0, -10], [45, 0, -10], [60, 0, -10]]",
                            "geometries = [[30, 0, -10], [60, 0, -10]]").replace("step = 10", "step = 35")
    reduced = acquisition.reduce_recording(_record(tmp_path / "partial", "ideal:beam_falloff=0.02", text))
    with pytest.raises(ValueError, match=r"no reference reading at theta_i = \[45.0\] deg"):
        reduced.fit_inputs("per-incidence")
    # the beam shows between 30 and 60 deg; the remedy named is not the refused one
    warning = next(w for w in reduced.warnings if "differs between lamp polar angles" in w)
    assert "read the standard at theta_i = [45.0] deg too" in warning and "--calibration" not in warning
    with pytest.raises(ValueError, match="calibration='bogus'"):
        reduced.fit_inputs("bogus")
    assert main(["fit", str(tmp_path / "partial"), "--model", "lambert", "--calibration", "per-incidence",
                 "--no-mcmc", "--quiet"]) == 2


def test_joined_recordings_merge_their_readings_per_incidence(recordings):
    parts = [acquisition.reduce_recording(recordings[name]) for name in ("ideal", "nonlinear")]
    joined = acquisition.combine_reduced(parts)
    assert [c.theta_i for c in joined.incidences] == [30.0, 45.0, 60.0]
    assert all(len(c.readings) == 2 for c in joined.incidences)
    np.testing.assert_allclose([sum(c.reading_weights) for c in joined.incidences], 1.0, rtol=1e-12)
    np.testing.assert_allclose(joined.theta_i, np.array([c.theta_i for c in joined.incidences])[joined.incidence],
                               atol=0.05)
    # two recordings, two series: four coefficients, independent between the recordings
    assert joined.linearity_covariance.shape == (4, 4)
    assert np.all(joined.linearity_covariance[:2, 2:] == 0.0)
    n = len(parts[0].radiance)
    assert np.all(joined.linearity_jacobian[:n, 2:] == 0.0) and np.all(joined.linearity_jacobian[n:, :2] == 0.0)
    dataset, _ = joined.fit_inputs("per-incidence")
    assert np.linalg.eigvalsh(dataset.covariance).min() > 0
    # the stored uncertainty (reduced.csv, the low_signal flags) is the covariance's: the
    # linearity component taken relative to the joint E_0, not to each part's own
    np.testing.assert_allclose(np.sqrt(np.diag(joined.covariance())), joined.radiance_sigma, rtol=1e-12)
    own = np.concatenate([p.budget["linearity"] for p in parts])
    assert np.max(np.abs(joined.budget["linearity"] / own - 1.0)) > 1e-3  # it did change


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A recording of three points without a reference standard."""
    return acquisition.reduce_recording(record(tmp_path_factory.mktemp("short") / "short", SHORT, SAMPLE, 4))


def test_a_recording_without_a_standard_is_refused_a_calibration_per_incidence(short):
    with pytest.raises(ValueError, match="no reference standard was measured"):
        short.fit_inputs("per-incidence")
    assert short.fit_inputs()[0].quantity == "normalised_radiance"


def test_a_joined_part_without_a_reference_is_calibrated_by_the_others_readings(recordings, short):
    """A recording without a standard, joined with one that read it at the part's lamp
    angle: its values are calibrated by those readings, as the value's planned angle says."""
    assert short.reference_irradiance is None
    joined = acquisition.combine_reduced([acquisition.reduce_recording(recordings["ideal"]), short])
    n = len(short.radiance)
    assert [joined.incidences[g].theta_i for g in joined.incidence[-n:]] == [30.0] * n
    dataset, _ = joined.fit_inputs("per-incidence")
    assert dataset.metadata["incidence_theta_i"][-n:] == [30.0] * n
    assert np.linalg.eigvalsh(dataset.covariance).min() > 0


def test_the_fit_matches_values_to_readings_by_the_planned_angle(recordings):
    """A stage whose readback tolerance is wider than a few hundredths of a degree records
    values further from the plan: the fit still calibrates each by the readings the
    reduction divided it by, and a subset keeps its values' angles."""
    from gonio.fitting import Dataset

    dataset, _ = acquisition.reduce_recording(recordings["beam"]).fit_inputs("per-incidence")
    weights = incidence_weights(dataset.metadata)
    moved = Dataset(dataset.theta_i + 0.2, dataset.phi_i, dataset.theta_r, dataset.phi_r, dataset.value,
                    dataset.sigma, quantity=dataset.quantity, metadata=dataset.metadata, covariance=dataset.covariance)
    rig = FitProblem("oren-nayar", moved, FIXED, alignment="theta_i_offset")._rig
    np.testing.assert_array_equal(rig.value_weights, weights)
    last = dataset.subset(np.arange(dataset.n)[-3:])
    assert last.metadata["incidence_theta_i"] == dataset.metadata["incidence_theta_i"][-3:]
    np.testing.assert_array_equal(incidence_weights(last.metadata), weights[-3:])


def test_the_rigs_prediction_calibrates_each_value_by_its_incidence(recordings):
    dataset, _ = acquisition.reduce_recording(recordings["beam"]).fit_inputs("per-incidence")
    weights = incidence_weights(dataset.metadata)
    assert weights.shape == (dataset.n, 3) and np.allclose(weights.sum(axis=1), 1.0)
    problem = FitProblem("oren-nayar", dataset, FIXED, alignment="theta_i_offset")
    rig = problem._rig
    assert rig.value_weights is not None
    # a lamp offset changes the standard's signal at each angle by its own cos(theta_i)
    # factor: each value is calibrated by its own angle's readings
    factor = rig.calibration_factor({"theta_i_offset": 0.3})
    per_reading = rig.reference[4]
    moved = RigPrediction._signal(rig.reference[0], (rig.reference[1][0] + 0.3, *rig.reference[1][1:]))
    expected = 1.0 / ((rig.reference[3] * moved / per_reading) @ weights.T)
    np.testing.assert_allclose(factor, expected, rtol=1e-12)
    assert np.ptp(factor) > 1e-3  # 30 and 60 deg differ by tan: 0.3 deg x (tan 60 - tan 30) = 6e-3


def test_the_incidence_deviations_are_the_covariance_they_claim():
    """_incidence_deviations against a Monte Carlo of the readings' errors: the covariance of
    E_k / E_0 - 1 between angles, and none with E_0's own error (the prior stays independent)."""
    from gonio.reduction.result import IncidenceCalibration, Reduced

    u = np.array([6e-5, 6e-5, 4e-5, 5e-5])
    weight = u**-2 / np.sum(u**-2)  # E_0's inverse-variance weights
    incidences = tuple(IncidenceCalibration(t, 1.0, s, w, (k,), (1.0,))
                       for k, (t, s, w) in enumerate(zip((30.0, 45.0, 60.0, 75.0), u, weight)))
    one = np.ones(1)
    reduced = Reduced(one, one, one, one, one, one, one, one, 1.0, 1e-5, "x", incidences=incidences)
    error = np.random.default_rng(0).standard_normal((200_000, 4)) * u
    common = error @ weight
    deviation = error - common[:, None]
    # 2e5 draws: sampling error of a covariance ~ sqrt(2 / 2e5) = 0.3 % of its scale; 2 %
    np.testing.assert_allclose(np.cov(deviation.T), reduced._incidence_deviations(), atol=0.02 * u.max() ** 2)
    cross = [np.cov(deviation[:, k], common)[0, 1] for k in range(4)]
    assert np.max(np.abs(cross)) < 0.01 * u.max() ** 2


def test_the_reductions_incidence_deviations_match_their_scatter_over_seeds(tmp_path):
    """E_k / E_0 - 1 of the reduction itself on a uniform beam (truth 0) at six angles, over
    four seeds of the emulated rig (its dark frames, monitor, stage and shot noise), against
    the covariance the reduction states (_incidence_deviations, whose E_k are taken as
    independent): the chi-square of 4 x 5 degrees of freedom (the six sum to 0 with E_0's
    weights) within its 99.9 % interval. Measured over 24 seeds (python
    benchmarks/bench_incidence_deviations.py): chi-square / dof 0.755 (120 dof, +-0.13),
    the stated errors conservative by about 15 %."""
    from scipy.stats import chi2

    total, dof = 0.0, 0
    for seed in range(4):
        reduced = acquisition.reduce_recording(record(tmp_path / f"seed{seed}", STANDARD_ANGLES, SAMPLE, seed))
        deviation = np.array([c.irradiance for c in reduced.incidences]) / reduced.reference_irradiance - 1.0
        covariance = reduced._incidence_deviations()
        total += float(deviation[:-1] @ np.linalg.solve(covariance[:-1, :-1], deviation[:-1]))
        dof += len(deviation) - 1
    assert chi2.ppf(0.0005, dof) < total < chi2.ppf(0.9995, dof), total / dof


def test_the_command_line_chooses_the_calibration_and_the_correction(recordings, tmp_path, capsys):
    from gonio.fitting import FitResult

    out = tmp_path / "fit"
    assert main(["fit", str(recordings["beam"]), "--model", "oren-nayar", "--fix", "ir_weight=1", "--calibration",
                 "per-incidence", "--no-mcmc", "--quiet", "--out", str(out)]) == 0  # adequate: the bias is gone
    assert FitResult.load(out).dataset.metadata["calibration"] == "per-incidence"
    assert main(["reduce", str(recordings["nonlinear"]), "--no-linearity-correction", "--out",
                 str(tmp_path / "raw")]) == 0
    assert "linearity correction was left out on request" in capsys.readouterr().out
    assert main(["reduce", str(recordings["nonlinear"]), "--out", str(tmp_path / "corrected")]) == 0
    assert "linearity " in capsys.readouterr().out  # the budget's component
    csv = tmp_path / "values.csv"
    csv.write_text("theta_i,phi_i,theta_r,phi_r,value,sigma\n30,0,10,0,0.3,0.01\n30,0,20,0,0.3,0.01\n")
    assert main(["fit", str(csv), "--model", "lambert", "--calibration", "per-incidence", "--no-mcmc"]) == 2

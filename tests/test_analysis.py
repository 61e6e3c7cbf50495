"""What a user takes away from the command line and the analysis API: own data in
(gonio.fitting.csv_table), joint fits, saved comparisons, partial recordings, progress
(gonio.analysis, gonio fit; docs/api.md, docs/data-format.md)."""
from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest

import gonio
from gonio import acquisition, protocols
from gonio.cli import main
from gonio.cli.run import emulated_rig
from gonio.fitting import Dataset, FitResult
from gonio.fitting.csv_table import ASSUMED_SIGMA, DROPPED_ROWS


def _oren_nayar_rows(noise=0.02, seed=1):
    """Lab-style rows of an Oren-Nayar sample (sigma 20 deg, rho 0.8) with 2 % relative noise."""
    view = np.arange(-70.0, 75.0, 5.0)
    theta_r, phi_r = np.abs(view), np.where(view >= 0, 0.0, 180.0)
    value = gonio.brdf("oren-nayar", 45, 0, theta_r, phi_r, sigma=20, rho=0.8)
    value = value * (1 + noise * np.random.default_rng(seed).standard_normal(value.size))
    return [(45.0, 0.0, tr, pr, v) for tr, pr, v in zip(theta_r, phi_r, value)]


def _write(path, header, rows, delimiter=";", transform=lambda row: row):
    lines = [delimiter.join(header)] + [delimiter.join(repr(float(x)) for x in transform(r)) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


MAPPING = "theta_i=incidence,phi_i=azi_i,theta_r=viewing,phi_r=azi_r,value=f"
OWN_COLUMNS = ("incidence", "azi_i", "viewing", "azi_r", "f")


# ------------------------------------------------------------------------------ own data
@pytest.mark.parametrize("delimiter", [";", "\t", ",", "  "])
def test_own_columns_any_delimiter_and_no_sigma_fit_with_the_noise_fitted(tmp_path, capsys, delimiter):
    path = _write(tmp_path / "lab.txt", OWN_COLUMNS, _oren_nayar_rows(), delimiter)
    out = tmp_path / "fit"
    code = main(["fit", str(path), "--model", "oren-nayar", "--fix", "ir_weight=1", "--columns", MAPPING,
                 "--no-mcmc", "--out", str(out), "--quiet"])
    assert code == 0  # adequate: no stated noise to call understated
    result = FitResult.load(out)
    assert result.dataset.metadata[ASSUMED_SIGMA] and result.jitter == "relative"
    assert result.least_squares.values["rel_jitter"] == pytest.approx(0.02, rel=0.35)
    assert result.least_squares.values["sigma"] == pytest.approx(20, abs=2)
    assert "states no uncertainties" in capsys.readouterr().out  # the summary says what was assumed


def test_missing_values_are_left_out_and_counted_and_text_is_still_an_error(tmp_path, capsys):
    rows = _oren_nayar_rows()
    path = _write(tmp_path / "lab.csv", OWN_COLUMNS + ("sigma",), rows, ",", lambda r: (*r, 0.02 * r[-1]))
    text = path.read_text().splitlines()
    text[3] = "45,0,12,0,NaN,0.01"
    text[7] = "45,0,14,,0.3,0.01"
    path.write_text("\n".join(text) + "\n")
    data = Dataset.from_csv(path, columns=dict(p.split("=") for p in MAPPING.split(",")))
    assert data.n == len(rows) - 2 and data.metadata[DROPPED_ROWS] == {"count": 2, "lines": [4, 8]}
    assert main(["fit", str(path), "--model", "lambert", "--columns", MAPPING, "--no-mcmc", "--quiet",
                 "--out", str(tmp_path / "f")]) in (0, 4, 5)
    assert "2 row(s) of the file had a missing value and were left out (lines 4, 8)" in capsys.readouterr().out
    text[3] = "45,0,12,0,oops,0.01"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError, match=r"lab.csv, line 4: column 'value' = 'oops' is not a number"):
        Dataset.from_csv(path, columns=dict(p.split("=") for p in MAPPING.split(",")))


def test_angles_in_radians_are_refused_with_a_hint_and_converted_when_declared(tmp_path, capsys):
    to_radians = lambda r: (math.radians(r[0]), math.radians(r[1]), math.radians(r[2]), math.radians(r[3]), r[4])  # noqa: E731
    path = _write(tmp_path / "rad.csv", ("theta_i", "phi_i", "theta_r", "phi_r", "value"), _oren_nayar_rows(), ",",
                  to_radians)
    assert main(["fit", str(path), "--model", "lambert", "--no-mcmc", "--quiet"]) == 2
    assert "look like radians" in capsys.readouterr().err and not (tmp_path / "rad.fit-lambert").exists()
    data = Dataset.from_csv(path, angle_unit="rad")
    np.testing.assert_allclose(data.theta_r, [r[2] for r in _oren_nayar_rows()], rtol=1e-12)


def test_a_column_mapping_naming_an_unknown_column_lists_the_files_columns(tmp_path, capsys):
    path = _write(tmp_path / "lab.csv", OWN_COLUMNS, _oren_nayar_rows(), ",")
    assert main(["fit", str(path), "--model", "lambert", "--columns", "theta_i=incident"]) == 2
    err = capsys.readouterr().err
    assert "theta_i (as 'incident')" in err and "'incidence'" in err
    assert main(["fit", str(path), "--model", "lambert", "--columns", "angle=incidence"]) == 2
    assert "not gonio's columns" in capsys.readouterr().err


def test_csv_header_values_are_json_and_the_covariance_travels_with_the_table(tmp_path):
    covariance = np.array([[4e-4, 1e-4], [1e-4, 9e-4]])
    data = Dataset(30, 0, [10, 20], 0, [0.3, 0.2], [0.02, 0.03], metadata={"aperture_sr": [0.003, 0.0009],
                                                                         "budget": {"texture": 2e-3}},
                   covariance=covariance)
    path = data.to_csv(tmp_path / "d.csv")
    header = [line for line in path.read_text().splitlines() if line.startswith("#")]
    assert '# budget: {"texture": 0.002}' in header and '# covariance: "d_covariance.npy"' in header
    back = Dataset.from_csv(path)
    np.testing.assert_array_equal(back.covariance, covariance)
    assert back.metadata["budget"] == {"texture": 2e-3}
    (tmp_path / "d_covariance.npy").unlink()
    with pytest.raises(FileNotFoundError, match="not beside it"):
        Dataset.from_csv(path)


# ------------------------------------------------------------------------------ comparisons
def test_several_models_write_the_comparison_and_fit_the_chosen_one_with_mcmc(tmp_path, capsys):
    path = _write(tmp_path / "lab.csv", OWN_COLUMNS + ("sigma",), _oren_nayar_rows(0.01), ",",
                  lambda r: (*r, 0.01 * r[-1]))
    out = tmp_path / "cmp"
    code = main(["fit", str(path), "--columns", MAPPING, "--model", "lambert", "--model", "oren-nayar",
                 "--fix", "ir_weight=1", "--out", str(out), "--max-steps", "4000", "--report", "--quiet"])
    assert code == 0
    result = FitResult.load(out)
    assert result.model == "oren-nayar" and result.mcmc is not None
    assert result.comparison["chosen"] == "oren-nayar (ir_weight=1)"
    saved = json.loads((out / "comparison.json").read_text())
    assert saved["result_id"] == result.result_id and {r["model"] for r in saved["rows"]} == {"lambert", "oren-nayar"}
    assert "chosen: oren-nayar (ir_weight=1)" in (out / "comparison.txt").read_text()
    assert "[[Model choice]]" in (out / "summary.txt").read_text()
    report = (out / "report.html").read_text()
    assert "<h2>Model choice</h2>" in report and 'class="chosen"' in report


def test_several_csv_files_are_fitted_jointly(tmp_path):
    a = _write(tmp_path / "a.csv", ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma"),
               _oren_nayar_rows(0.01, 1), ",", lambda r: (*r, 0.01 * r[-1]))
    b = _write(tmp_path / "b.csv", ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma"),
               [(60.0, 0.0, *r[2:]) for r in _oren_nayar_rows(0.01, 2)], ",", lambda r: (*r, 0.01 * r[-1]))
    assert main(["fit", str(a), str(b), "--model", "lambert", "--no-mcmc", "--quiet"]) in (0, 4)
    result = FitResult.load(tmp_path / "a+b.fit-lambert")
    assert result.dataset.n == 58 and len(result.dataset.incidences()[0]) == 2


# ------------------------------------------------------------------------------ recordings
SMALL = """
[protocol]
name = "small-{name}"
[sample]
label = "matte"
[reference]
label = "diffuse standard"
reflectance = 0.99
geometries = [[{theta}, 0, -10]]
[[block]]
theta_i = {theta}
view = [-40, -20, 0, 20, 50]
"""


def _record(tmp_path, name, theta, seed):
    protocol = protocols.loads(SMALL.format(name=name, theta=theta), source=f"{name}.toml")
    folder = tmp_path / name
    with emulated_rig("oren-nayar:sigma=25,rho=0.8", seed, name=f"analysis-{name}", realism="ideal") as (
            rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                 change_sample=lambda which, **how: change(which, 0.99, **how))
    return folder


def test_recordings_are_fitted_jointly_from_the_command_line_and_the_api(tmp_path):
    first, second = _record(tmp_path, "one", 30, 1), _record(tmp_path, "two", 60, 2)
    assert main(["fit", str(first), str(second), "--model", "oren-nayar", "--fix", "ir_weight=1", "--no-mcmc",
                 "--quiet"]) in (0, 4, 5)
    result = FitResult.load(tmp_path / "one+two.fit-oren-nayar")
    assert result.dataset.n == 10 and result.dataset.quantity == "radiance"
    assert "scale" in result.priors  # the reference standard's prior on the joint E_0
    api = gonio.fit_recording([first, second], models="oren-nayar", fixed={"ir_weight": 1}, mcmc=False)
    assert api.least_squares.values == pytest.approx(result.least_squares.values, rel=1e-9)
    # the emulated sample's truth travels with the data into the summary
    summary = result.summary()
    assert "[[Truth]] (the emulated sample oren-nayar:sigma=25,rho=0.8)" in summary
    assert "(no interval: least squares only)" in summary


def test_the_truth_table_flags_a_truth_outside_its_interval():
    from gonio.fitting.truth import known_truth, truth_lines

    rows = [{"name": "sigma", "value": 27.0, "median": 27.0, "p2_5": 26.0, "p97_5": 28.0, "unit": "deg"},
            {"name": "rho", "value": 0.8, "median": 0.8001, "p2_5": 0.79, "p97_5": 0.81, "unit": "-"}]
    lines, bias = truth_lines(rows, {"sigma": 25.0, "rho": 0.8, "k": 1.0}, "oren-nayar")
    assert "NO" in lines[1] and "yes" in lines[2] and "not a parameter of oren-nayar" in lines[3]
    assert bias == ["BIAS: sigma is +2 deg from the truth, 2.0 times the interval's half-width: oren-nayar does "
                    "not reproduce the emulated sample within these data's noise"]
    assert known_truth({}) is None


def test_an_interrupted_recording_without_its_reference_says_what_is_missing(tmp_path, capsys):
    folder = _record(tmp_path, "partial", 30, 3)
    points = (folder / "points.csv").read_text().splitlines()
    kept = [line for line in points if ",reference standard," not in line]  # cut before the standard
    kept = kept[:4]  # header + 3 sample points
    (folder / "points.csv").write_text("\n".join(kept) + "\n")
    metadata = json.loads((folder / "metadata.json").read_text())
    metadata["status"] = "interrupted"
    (folder / "metadata.json").write_text(json.dumps(metadata))
    assert main(["fit", str(folder), "--model", "lambert", "--no-mcmc", "--out", str(tmp_path / "f")]) in (0, 4, 5)
    out = capsys.readouterr().out
    assert "the recording is interrupted: 3 of 5 planned sample points measured" in out
    assert f"gonio run partial.toml --out {folder} --resume" in out
    assert "reference standard was planned but not measured" in out and "not calibrated BRDF" in out


# ------------------------------------------------------------------------------ the API and progress
def test_the_api_result_has_a_short_repr_and_an_html_view(tmp_path):
    path = _write(tmp_path / "lab.csv", OWN_COLUMNS, _oren_nayar_rows(), ",")
    result = gonio.fit_recording(path, models=["lambert", "oren-nayar"], fixed={"ir_weight": 1}, mcmc=False,
                                 columns=dict(p.split("=") for p in MAPPING.split(",")))
    text = repr(result)
    assert text.startswith("<FitResult oren-nayar to 29 brdf values") and len(text) < 200
    html = result._repr_html_()
    assert "<table>" in html and 'class="comparison"' in html
    from gonio.report import write_report

    assert callable(write_report)


def test_a_slow_least_squares_fit_reports_its_progress(monkeypatch, caplog):
    from gonio.fitting import fit, least_squares

    monkeypatch.setattr(least_squares, "HEARTBEAT_SECONDS", 0.0)
    data = Dataset(45, 0, np.arange(0, 80, 10.0), 0, gonio.brdf("lambert", 45, 0, np.arange(0, 80, 10.0), 0, rho=0.5),
                   0.01)
    with caplog.at_level(logging.INFO, logger="gonio.fitting"):
        fit(data, "lambert", mcmc=False)
    assert any("least squares of lambert: start 1 of 6" in r.message for r in caplog.records)


def test_debug_works_after_the_subcommand(tmp_path):
    from gonio.cli import CLIError

    with pytest.raises(CLIError, match="no such file"):  # propagated, traceback and all
        main(["fit", str(tmp_path / "missing.csv"), "--model", "lambert", "--debug"])
    assert main(["fit", str(tmp_path / "missing.csv"), "--model", "lambert"]) == 2


def test_posterior_file_has_the_predictive_the_observed_data_and_the_geometry(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from gonio.fitting.diagnostics import arviz

    az = arviz()
    path = _write(tmp_path / "lab.csv", ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma"),
                  _oren_nayar_rows(0.01), ",", lambda r: (*r, 0.01 * r[-1]))
    result = gonio.fit_recording(path, models="lambert", jitter="relative", max_steps=3000)
    result.save(tmp_path / "fit")
    data = az.from_netcdf(tmp_path / "fit" / "posterior.nc")
    assert data.posterior_predictive["y"].shape[-1] == result.dataset.n
    np.testing.assert_array_equal(data.observed_data["y"].values, result.dataset.value)
    np.testing.assert_array_equal(data.constant_data["theta_r"].values, result.dataset.theta_r)
    # the replicated data scatter about the data as the fitted noise says (relative ~1 %)
    spread = np.std(data.posterior_predictive["y"].values.reshape(-1, result.dataset.n), axis=0)
    assert np.median(spread / result.dataset.value) == pytest.approx(
        math.hypot(0.01, result.best_values()["rel_jitter"]), rel=0.3)
    az.plot_ppc(data, num_pp_samples=20)  # ArviZ's posterior predictive check runs on the file
    with np.load(tmp_path / "fit" / "chain.npz") as chain:
        assert list(chain["names"]) == list(result.free) and chain["chain"].shape[-1] == len(result.free)


def test_model_specs_fix_values_per_candidate_as_curet_fit_does(tmp_path, capsys):
    path = _write(tmp_path / "lab.csv", OWN_COLUMNS + ("sigma",), _oren_nayar_rows(0.01), ",",
                  lambda r: (*r, 0.01 * r[-1]))
    out = tmp_path / "variants"
    assert main(["fit", str(path), "--columns", MAPPING, "--model", "oren-nayar:ir_weight=1", "--model",
                 "oren-nayar", "--no-mcmc", "--quiet", "--out", str(out)]) in (0, 4)
    labels = {row["label"] for row in FitResult.load(out).comparison["rows"]}
    assert labels == {"oren-nayar (ir_weight=1)", "oren-nayar"}
    assert main(["fit", str(path), "--columns", MAPPING, "--model", "lambert", "--fix", "sigma=3"]) == 2
    assert "belong to none of the models" in capsys.readouterr().err

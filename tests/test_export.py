"""``gonio export`` (gonio.export, docs/export.md): every file read back by a reader written
here from the format's description, not from the writer's code.

The MERL reader follows the database's own description (Matusik et al. 2003 and its
``BRDFRead.cpp``): three int32 (90, 90, 180), then 90 x 90 x 180 float64 per channel, red,
green, blue, scaled on reading by 1/1500, 1.15/1500, 1.66/1500; cell (i, j, k) is
theta_h index i (theta_h = (i/90)^2 90 deg at its lower edge), theta_d = j deg, phi_d = k
deg at their lower edges; docs/export.md states that the writer samples each cell at its
centre in index space.
"""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import gonio
from gonio.cli import main
from gonio.export import export
from gonio.fitting import Dataset, fit

SPEC = "oren-nayar:sigma=30,rho=0.9"
SCALES = np.array([1.0, 1.15, 1.66]) / 1500.0
# The writer and this reader evaluate the same formula at the same angles, computed by two
# different paths (rotations here, the writer's own trigonometry): the angles agree to about
# 1e-13 deg, so 1e-6 relative leaves room for rounding only, never for a wrong cell.
RTOL = 1e-6


# ---------------------------------------------------------------------- readers
def read_merl(path):
    """The three channels (3, 90, 90, 180) as a MERL reader returns them, and the header."""
    raw = path.read_bytes()
    header = tuple(np.frombuffer(raw[:12], "<i4"))
    values = np.frombuffer(raw[12:], "<f8")
    assert values.size == 3 * 90 * 90 * 180
    return header, values.reshape(3, 90, 90, 180) * SCALES[:, None, None, None]


def _rotate(v, axis, angle):
    """Rotate vectors v (..., 3) by angle [rad] about a coordinate axis (right-handed)."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    if axis == "y":
        return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def cell_directions():
    """Incoming and outgoing unit vectors of every cell's centre (90, 90, 180, 3):
    Rusinkiewicz's half/difference frame, phi_h = 0."""
    i, j, k = np.meshgrid(np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    theta_h = ((i + 0.5) / 90.0) ** 2 * (np.pi / 2)
    theta_d, phi_d = np.radians(j + 0.5), np.radians(k + 0.5)
    diff = np.stack([np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], axis=-1)
    normal = np.array([0.0, 0.0, 1.0])
    w_in = _rotate(diff, "y", theta_h)
    half = _rotate(np.broadcast_to(normal, diff.shape), "y", theta_h)
    w_out = 2 * np.sum(w_in * half, axis=-1)[..., None] * half - w_in
    return w_in, w_out


def merl_index(w_in, w_out):
    """MERL's lookup of (in, out) directions: half/difference angles, then indices."""
    half = w_in + w_out
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    theta_h = np.arccos(np.clip(half[..., 2], -1, 1))
    phi_h = np.arctan2(half[..., 1], half[..., 0])
    diff = _rotate(_rotate(w_in, "z", -phi_h), "y", -theta_h)
    theta_d = np.arccos(np.clip(diff[..., 2], -1, 1))
    phi_d = np.arctan2(diff[..., 1], diff[..., 0])
    phi_d = np.where(phi_d < 0, phi_d + np.pi, phi_d)
    i = np.clip(np.sqrt(np.degrees(theta_h) * 90.0).astype(int), 0, 89)
    j = np.clip((np.degrees(theta_d)).astype(int), 0, 89)
    k = np.clip((np.degrees(phi_d)).astype(int), 0, 179)
    return i, j, k


def angles(w):
    return np.degrees(np.arccos(np.clip(w[..., 2], -1, 1))), np.degrees(np.arctan2(w[..., 1], w[..., 0]))


def read_csv(path):
    """The ``# key: JSON`` header lines and the table as a dict of columns."""
    header, rows = {}, []
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            key, _, value = line[1:].partition(":")
            header[key.strip()] = json.loads(value)
        else:
            rows.append(line.split(","))
    names = rows[0]
    table = np.array(rows[1:], float)
    return header, {name: table[:, n] for n, name in enumerate(names)}


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def spec_merl(tmp_path_factory):
    out = tmp_path_factory.mktemp("merl") / "plaster.binary"
    export(SPEC, "merl", out)
    return out


@pytest.fixture(scope="module")
def fit_folder(tmp_path_factory):
    """A short MCMC fit of oren-nayar to synthetic BRDF at theta_i = 30, 60 deg and
    theta_r = 0-70 deg, saved (the chain need not converge for the export's checks)."""
    theta_i, theta_r = np.meshgrid([30.0, 60.0], np.arange(0.0, 71.0, 10.0), indexing="ij")
    value = gonio.brdf("oren-nayar", theta_i, 0.0, theta_r, 0.0, rho=0.8, sigma=25.0).ravel()
    noisy = value * (1 + 0.01 * np.random.default_rng(3).normal(size=value.size))
    data = Dataset(theta_i.ravel(), 0.0, theta_r.ravel(), 0.0, noisy, 0.01 * value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the short chain is flagged as not converged
        result = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=True, max_steps=300, n_walkers=16, seed=0)
    folder = tmp_path_factory.mktemp("fit") / "fit"
    result.save(folder)
    return folder


# ---------------------------------------------------------------------- MERL
def test_merl_header_and_size(spec_merl):
    header, _ = read_merl(spec_merl)
    assert header == (90, 90, 180)
    assert spec_merl.stat().st_size == 12 + 3 * 8 * 1_458_000


def test_merl_cell_centres_map_back_to_their_cells():
    """The sample point of every cell (cell centre) is looked up by MERL's own mapping to
    that same cell: the convention of the docs is self-consistent."""
    w_in, w_out = cell_directions()
    valid = (w_in[..., 2] > 0) & (w_out[..., 2] > 0)
    i, j, k = merl_index(w_in[valid], w_out[valid])
    expect = np.nonzero(valid)
    assert np.array_equal(i, expect[0]) and np.array_equal(j, expect[1]) and np.array_equal(k, expect[2])


def test_merl_values_equal_the_model_at_every_valid_cell(spec_merl):
    _, rgb = read_merl(spec_merl)
    w_in, w_out = cell_directions()
    valid = (w_in[..., 2] > 0) & (w_out[..., 2] > 0)
    (ti, pi_), (tr, pr) = angles(w_in[valid]), angles(w_out[valid])
    model = gonio.brdf("oren-nayar", ti, pi_, tr, pr, sigma=30.0, rho=0.9)
    for channel in rgb:  # grey: the same value in every channel once scaled
        np.testing.assert_allclose(channel[valid], model, rtol=RTOL, atol=0)
    assert valid.sum() > 0.5 * valid.size


def test_merl_invalid_cells_are_negative(spec_merl):
    _, rgb = read_merl(spec_merl)
    w_in, w_out = cell_directions()
    valid = (w_in[..., 2] > 0) & (w_out[..., 2] > 0)
    assert (~valid).any()
    assert (rgb[:, ~valid] < 0).all()
    assert (rgb[:, valid] >= 0).all()


def test_merl_sidecar_of_a_spec_says_there_is_no_posterior(spec_merl):
    with np.load(str(spec_merl) + ".uncertainty.npz") as side:
        assert not bool(side["has_posterior"]) and int(side["n_draws"]) == 0
        assert "sd" not in side.files
        assert side["valid"].shape == (90, 90, 180)
        assert json.loads(str(side["description"]))["model"] == "oren-nayar"
        w_in, w_out = cell_directions()
        assert np.array_equal(side["valid"], (w_in[..., 2] > 0) & (w_out[..., 2] > 0))


def test_merl_of_a_fit_has_a_sane_sd_per_cell(fit_folder, tmp_path):
    out = tmp_path / "fit.binary"
    assert main(["export", str(fit_folder), "--format", "merl", "--out", str(out)]) == 0
    _, rgb = read_merl(out)
    with np.load(str(out) + ".uncertainty.npz") as side:
        sd, valid, within = side["sd"], side["valid"], side["within_data"]
        assert bool(side["has_posterior"]) and 2 <= int(side["n_draws"]) <= 50
    assert sd.shape == (90, 90, 180)
    lit = valid & (rgb[0] > 0)
    assert (sd[lit] > 0).all() and np.isfinite(sd).all()
    # 1 % noise on 16 values: the BRDF is known to about a percent, not to 1e-6 nor 50 %
    relative = sd[lit & within] / rgb[0][lit & within]
    assert 1e-4 < np.median(relative) < 0.1
    assert within.any() and (valid & ~within).any() and not (within & ~valid).any()


# ---------------------------------------------------------------------- CSV
def test_csv_of_a_spec_equals_the_model_at_every_row(tmp_path):
    out = tmp_path / "plaster.csv"
    export(SPEC, "csv", out)
    header, table = read_csv(out)
    assert list(table) == ["theta_i", "phi_i", "theta_r", "phi_r", "brdf"]
    assert header["brdf_unit"] == "1/sr" and header["n_draws"] == 0
    assert len(table["brdf"]) == 18 * 18 * 13  # theta_i, theta_r 0-85 by 5, dphi 0-180 by 15
    model = gonio.brdf("oren-nayar", table["theta_i"], table["phi_i"], table["theta_r"], table["phi_r"],
                       sigma=30.0, rho=0.9)
    np.testing.assert_allclose(table["brdf"], model, rtol=RTOL, atol=0)


def test_csv_of_a_fit_has_quantiles_sd_and_the_data_range(fit_folder, tmp_path):
    out = tmp_path / "fit.csv"
    assert main(["export", str(fit_folder), "--format", "csv", "--out", str(out)]) == 0
    header, t = read_csv(out)
    for name in ("brdf_median", "brdf_p2_5", "brdf_p97_5", "brdf_sd", "within_data"):
        assert name in t
    assert 2 <= header["n_draws"] <= 200
    assert (t["brdf_sd"] > 0).all()
    assert (t["brdf_p2_5"] <= t["brdf_median"]).all() and (t["brdf_median"] <= t["brdf_p97_5"]).all()
    assert (t["brdf_p2_5"] < t["brdf_p97_5"]).all()
    # brdf is the model at the posterior medians of the parameters: its values read back
    values = header["values"]
    model = gonio.brdf("oren-nayar", t["theta_i"], t["phi_i"], t["theta_r"], t["phi_r"], **values)
    np.testing.assert_allclose(t["brdf"], model, rtol=RTOL, atol=0)
    # the data: theta_i 30-60, theta_r 0-70, margin 5 deg, incidence and view exchangeable
    def inside(a, lo, hi):
        return (a >= lo - 5) & (a <= hi + 5)
    expect = (inside(t["theta_i"], 30, 60) & inside(t["theta_r"], 0, 70)) | \
             (inside(t["theta_r"], 30, 60) & inside(t["theta_i"], 0, 70))
    assert np.array_equal(t["within_data"] == 1, expect)
    assert expect.any() and (~expect).any()


def test_csv_grid_option(tmp_path):
    out = tmp_path / "g.csv"
    assert main(["export", "lambert:rho=0.5", "--format", "csv", "--out", str(out),
                 "--grid", "theta_i=10:30:10", "--grid", "dphi=90"]) == 0
    _, t = read_csv(out)
    assert len(t["brdf"]) == 3 * 18 * 1
    np.testing.assert_allclose(t["brdf"], 0.5 / np.pi, rtol=1e-12)


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize("source, fmt, out, words", [
    (SPEC, "obj", "x.csv", ["format", "'obj'", "merl", "csv"]),
    ("no-such-model", "csv", "x.csv", ["unknown model", "no-such-model"]),
    ("oren-nayar:sigma=300", "csv", "x.csv", ["sigma", "300", "[0, 90]"]),
    ("oren-nayar:colour=3", "csv", "x.csv", ["colour"]),
    (SPEC, "merl", "missing/x.binary", ["missing", "does not exist"]),
])
def test_bad_input_is_refused_naming_what_was_wrong(tmp_path, source, fmt, out, words):
    with pytest.raises(ValueError) as caught:
        export(source, fmt, tmp_path / out)
    for word in words:
        assert word in str(caught.value)
    assert not any(tmp_path.iterdir())


def test_an_existing_file_is_not_replaced_without_overwrite(tmp_path, capsys):
    out = tmp_path / "mine.csv"
    out.write_text("not gonio's\n")
    assert main(["export", SPEC, "--format", "csv", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == "not gonio's\n"
    assert main(["export", SPEC, "--format", "csv", "--out", str(out), "--overwrite"]) == 0


def test_cli_names_a_missing_folder(tmp_path, capsys):
    assert main(["export", SPEC, "--format", "csv", "--out", str(tmp_path / "nope" / "x.csv")]) == 2
    assert "does not exist" in capsys.readouterr().err


# ---------------------------------------------------------------------- ASTM E1392 rows
# The reader below follows docs/export.md ("ASTM E1392 rows"): lines "# key: JSON value",
# then a line of comma-separated column names, then one comma-separated row per geometry;
# angles in deg, phi_s measured from the plane of incidence (0 on its specular side, 180 on
# the source's side), so that gonio's view azimuth is phi_r = phi_i + phi_s + 180 deg;
# cc_brdf = brdf cos(theta_s).
ASTM_ANGLES = ["theta_i", "phi_i", "theta_s", "phi_s"]
RECORDED = """
[protocol]
name = "astm-export"
[sample]
label = "matte tile"
[reference]
label = "diffuse standard"
reflectance = 0.99
reflectance_uncertainty = 0.005
geometries = [[30, 0, -10], [60, 0, -10]]
[[block]]
theta_i = [30, 60]
view = [-50, -20, 0, 20, 45]
"""


def read_astm(path):
    """An ASTM export: the same ``# key: JSON`` header and comma-separated table as the CSV."""
    return read_csv(path)


def gonio_view_azimuth(t):
    """gonio's phi_r [deg] of a row, from the documented convention."""
    return t["phi_i"] + t["phi_s"] + 180.0


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A calibrated recording of an emulated oren-nayar sample (idealised rig, to be quick)."""
    from tests.emulated_recording import record

    return record(tmp_path_factory.mktemp("astm") / "rec", RECORDED, "oren-nayar:sigma=25,rho=0.8", seed=5)


def test_astm_of_a_spec_equals_the_model_at_every_row(tmp_path):
    out = tmp_path / "plaster.astm"
    assert [p.name for p in export(SPEC, "astm", out)] == ["plaster.astm", "plaster.astm.uncertainty.npz"]
    header, t = read_astm(out)
    assert header["format"] == "gonio astm-e1392 1" and header["data"] == "model" and header["measured"] is False
    assert list(t) == ASTM_ANGLES + ["brdf", "cc_brdf"] == header["columns"]
    assert header["units"] == ["deg"] * 4 + ["1/sr"] * 2 and header["rows"] == 18 * 18 * 13
    assert header["polarization"].startswith("unpolarized") and header["wavelength_nm"] is None
    assert ((t["phi_s"] > -180) & (t["phi_s"] <= 180)).all()
    model = gonio.brdf("oren-nayar", t["theta_i"], t["phi_i"], t["theta_s"], gonio_view_azimuth(t), sigma=30.0,
                       rho=0.9)
    np.testing.assert_allclose(t["brdf"], model, rtol=RTOL, atol=0)
    # cos theta_s computed here and by the writer from the same angles: rounding only
    np.testing.assert_allclose(t["cc_brdf"], t["brdf"] * np.cos(np.radians(t["theta_s"])), rtol=1e-12, atol=1e-300)
    # phi_s = 180 is the source's side: Oren-Nayar back-scatters (sec. 4), so the retro
    # row is brighter than the specular-side row at theta_i = theta_s = 45 deg
    at = (t["theta_i"] == 45) & (t["theta_s"] == 45)
    assert t["brdf"][at & (t["phi_s"] == 180)][0] > 1.2 * t["brdf"][at & (t["phi_s"] == 0)][0]
    with np.load(str(out) + ".uncertainty.npz") as side:
        assert not bool(side["has_posterior"]) and int(side["n_draws"]) == 0 and "sd" not in side.files
        np.testing.assert_array_equal(side["brdf_at_values"], t["brdf"])


def test_astm_of_a_fit_has_the_posterior_median_and_its_uncertainty(fit_folder, tmp_path):
    out = tmp_path / "fit.astm"
    assert main(["export", str(fit_folder), "--format", "astm", "--out", str(out), "--grid", "dphi=0:180:90"]) == 0
    header, t = read_astm(out)
    assert header["data"] == "fit" and list(t) == ASTM_ANGLES + ["brdf", "u_brdf", "cc_brdf", "u_cc_brdf",
                                                                "within_data"]
    assert header["fit"]["points"] == 16 and "posterior median" in header["brdf_column"]
    with np.load(str(out) + ".uncertainty.npz") as side:
        median, sd, low, high = (side[k] for k in ("median", "sd", "p2_5", "p97_5"))
        at_values = side["brdf_at_values"]
    # the file's values are the side-car's, written with 17 digits: equal when read back
    np.testing.assert_array_equal(t["brdf"], median)
    np.testing.assert_array_equal(t["u_brdf"], sd)
    assert (low <= t["brdf"]).all() and (t["brdf"] <= high).all() and (t["u_brdf"] > 0).all()
    model = gonio.brdf("oren-nayar", t["theta_i"], t["phi_i"], t["theta_s"], gonio_view_azimuth(t), **header["values"])
    np.testing.assert_allclose(at_values, model, rtol=RTOL, atol=0)
    # 1 % noise on 16 values: known to about a percent; the median of the BRDF sits within
    # a few standard deviations of the BRDF at the median parameters
    inside = t["within_data"] == 1
    assert 1e-4 < np.median(t["u_brdf"][inside] / t["brdf"][inside]) < 0.1
    assert np.all(np.abs(t["brdf"] - model) <= 3 * t["u_brdf"])
    np.testing.assert_allclose(t["u_cc_brdf"], t["u_brdf"] * np.cos(np.radians(t["theta_s"])), rtol=1e-12)
    assert inside.any() and (~inside).any()


def test_astm_of_a_recording_equals_the_reduced_rows(recording, tmp_path):
    from gonio import reduction
    from gonio.data import read_metadata

    out = tmp_path / "rec.astm"
    assert main(["export", str(recording), "--format", "astm", "--out", str(out)]) == 0
    header, t = read_astm(out)
    expected = reduction.reduce_recording(recording).brdf()
    assert header["data"] == "measured" and header["rows"] == expected.n == 10
    for name, column in (("theta_i", "theta_i"), ("phi_i", "phi_i"), ("theta_s", "theta_r"), ("brdf", "value"),
                         ("u_brdf", "sigma")):
        np.testing.assert_array_equal(t[name], getattr(expected, column))  # 17 digits: exact
    np.testing.assert_allclose(np.mod(gonio_view_azimuth(t) - expected.phi_r + 180, 360) - 180, 0, atol=1e-9)
    np.testing.assert_allclose(t["cc_brdf"], expected.value * np.cos(np.radians(expected.theta_r)), rtol=1e-12)
    assert (t["repeats"] == 1).all() and set(t["low_signal"]) <= {0, 1}
    with np.load(str(out) + ".uncertainty.npz") as side:
        np.testing.assert_array_equal(side["covariance"], expected.covariance)
        parts = [side[name] for name in side.files if name.startswith("u_")]
    np.testing.assert_allclose(np.sqrt(np.sum(np.square(parts), axis=0)), t["u_brdf"], rtol=1e-9)
    meta = read_metadata(recording)
    instruments = meta["experiment"]["instruments"]
    assert header["incident_beam"]["source"] == instruments["lamp"]
    assert header["receiver"]["detector"] == instruments["camera"]
    assert header["receiver"]["solid_angle_sr"] == meta["rig"]["aperture_sr"][1]
    assert header["measured_at"]["started"] == meta["started"] and header["measured_at"]["status"] == "complete"
    assert header["sample"]["label"] == "matte tile"
    assert header["reference_standard"]["label"] == "diffuse standard"
    assert header["reference_standard"]["reflectance_uncertainty"] == 0.005
    assert header["wavelength_nm"] == 550.0 and "unpolarized" in header["polarization"]
    assert "IDEALISED" in header["instrument"]["note"]  # the idealised rig is named as such


def test_astm_refuses_what_it_cannot_export(recording, tmp_path):
    neither = tmp_path / "notes"
    neither.mkdir()
    (neither / "readme.txt").write_text("not gonio's\n")
    cases = [((SPEC, "astm-e1392"), ["format", "'astm-e1392'", "merl", "csv", "astm"]),
             ((neither, "astm"), ["notes", "neither a fit result", "nor a recording", "result.json", "points.csv"]),
             ((recording, "merl"), ["is a recording", "--format astm", "gonio fit"]),
             ((recording, "csv"), ["is a recording", "--format astm"])]
    for (source, fmt), words in cases:
        with pytest.raises(ValueError) as caught:
            export(source, fmt, tmp_path / "x.astm")
        for word in words:
            assert word in str(caught.value), (source, fmt, word)
    with pytest.raises(ValueError, match="measured geometries; grid and draws"):
        export(recording, "astm", tmp_path / "x.astm", grid={"dphi": "0"})
    assert not (tmp_path / "x.astm").exists()


def test_astm_refuses_a_recording_without_reference_standard(tmp_path):
    from tests.emulated_recording import record

    text = RECORDED.split("[reference]")[0] + "[[block]]\ntheta_i = 30\nview = [0, 20]\n"
    folder = record(tmp_path / "relative", text, "lambert:rho=0.5", seed=1)
    with pytest.raises(ValueError, match="no reference standard") as caught:
        export(folder, "astm", tmp_path / "x.astm")
    assert "relative" in str(caught.value) and not (tmp_path / "x.astm").exists()


def test_astm_does_not_replace_a_file_without_overwrite(tmp_path, capsys):
    out = tmp_path / "mine.astm"
    side = tmp_path / "mine.astm.uncertainty.npz"
    side.write_text("not gonio's\n")  # the side-car alone is enough to refuse
    assert main(["export", "lambert:rho=0.5", "--format", "astm", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and side.read_text() == "not gonio's\n" and not out.exists()
    assert main(["export", "lambert:rho=0.5", "--format", "astm", "--out", str(out), "--overwrite"]) == 0
    np.testing.assert_allclose(read_astm(out)[1]["brdf"], 0.5 / np.pi, rtol=1e-12)


# ---------------------------------------------------------------------- MERL time warning
def test_merl_valid_cells_count_matches_the_cells_above_the_horizon():
    from gonio.export import MERL_VALID_CELLS

    w_in, w_out = cell_directions()
    assert MERL_VALID_CELLS == int(((w_in[..., 2] > 0) & (w_out[..., 2] > 0)).sum())


def test_merl_time_estimate_is_the_measured_rate_times_the_cells(monkeypatch, fit_folder):
    from gonio import export as module

    monkeypatch.setattr(module, "_seconds_per_cell", lambda function, geometry: 1e-3)
    spec = module.material_of("oren-nayar-exact:sigma=20")
    assert module.merl_seconds(spec) == pytest.approx(1e-3 * module.MERL_VALID_CELLS, rel=1e-12)
    fit = module.material_of(str(fit_folder))  # the values, then the draws
    assert module.merl_seconds(fit) == pytest.approx(2e-3 * module.MERL_VALID_CELLS, rel=1e-12)
    message = module.merl_time_warning(spec)
    assert "18 minutes" in message and "oren-nayar-tabulated" in message and "oren-nayar-exact" in message
    monkeypatch.setattr(module, "_seconds_per_cell", lambda function, geometry: 1e-8)
    assert module.merl_time_warning(spec) is None


def test_merl_export_warns_before_it_starts(monkeypatch, tmp_path, capsys):
    from gonio import export as module

    monkeypatch.setattr(module, "_seconds_per_cell", lambda function, geometry: 1e-4)  # 110 s
    out = tmp_path / "l.binary"
    assert main(["export", "lambert:rho=0.5", "--format", "merl", "--out", str(out), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "warning: a MERL export of lambert is estimated to take about 110 s" in captured.err
    with pytest.warns(module.SlowExportWarning, match="estimated to take"):
        export("lambert:rho=0.5", "merl", tmp_path / "m.binary")
    # up front: the warning comes before the writing starts
    events = []
    monkeypatch.setattr(module, "write_merl", lambda *args, **kwargs: events.append("write") or [])
    export("lambert:rho=0.5", "merl", tmp_path / "n.binary", warn=events.append)
    assert len(events) == 2 and events[0].startswith("a MERL export") and events[1] == "write"


def test_merl_time_estimate_of_the_exact_model_is_minutes():
    """The real rate, measured on a few hundred cells (about 0.3 s): the exact model's
    MERL export takes minutes (about 1 ms per cell), the closed form's well under 30 s."""
    from gonio.export import MERL_WARN_SECONDS, material_of, merl_seconds, merl_time_warning

    assert merl_seconds(material_of("oren-nayar-exact")) > 5 * MERL_WARN_SECONDS
    assert merl_time_warning(material_of("oren-nayar")) is None

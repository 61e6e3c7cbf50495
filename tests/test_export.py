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

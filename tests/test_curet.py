"""CUReT reader (Dana, van Ginneken, Nayar & Koenderink, ACM TOG 18(1), 1999) and a KvD
least-squares fit to a measured sample (Koenderink & van Doorn 1998, eq 26-31)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.curet import default_directory, read_curet, read_curet_brdf, read_curet_geometry
from gonio.geometry import angle_between
from gonio.models import kvd

CURET_DIR = default_directory()
needs_data = pytest.mark.skipif(not (CURET_DIR / "abrdf.dat").exists(), reason=f"CUReT files not found in {CURET_DIR}")


@pytest.fixture(scope="module")
def curet():
    return read_curet(CURET_DIR)


@needs_data
def test_shapes_numbers_and_degrees(curet):
    assert curet.brdf.shape == (61, 205)
    assert curet.sample_numbers.tolist() == list(range(1, 62))
    for theta in (curet.theta_i, curet.theta_r):
        assert theta.min() >= 0.0 and theta.max() < 84.0  # measured max 83.88 deg
    # first row of table.txt: 1.389566 rad viewing, 1.374447 rad illumination
    assert curet.theta_r[0] == pytest.approx(np.degrees(1.389566))
    assert curet.theta_i[0] == pytest.approx(np.degrees(1.374447))


@needs_data
def test_lamp_camera_angle_takes_seven_multiples_of_22_5_deg_and_no_retro(curet):
    """Checked README statement: camera and lamp never coincide; their separation is
    22.5 k deg, k = 1..7 (to 0.01 deg, the 6-digit rounding of the radians)."""
    separation = angle_between(curet.theta_i, curet.phi_i, curet.theta_r, curet.phi_r)
    k = separation / 22.5
    np.testing.assert_allclose(k, np.round(k), atol=0.01 / 22.5)
    assert sorted(set(np.round(k).astype(int))) == [1, 2, 3, 4, 5, 6, 7]


@needs_data
def test_negative_values_are_kept_and_flagged(curet):
    assert curet.negative.sum() == 29
    assert curet.brdf.min() == pytest.approx(-0.016)
    moss = curet.sample(61)
    assert moss.negative.sum() == 28 and (moss.brdf[moss.negative] < 0).all()


@needs_data
def test_sample_names_from_the_database_list(curet):
    assert curet.sample("velvet").number == 7
    assert curet.sample("sandpaper").number == 6
    assert curet.sample(30).name == "plaster_b zoomed"
    assert curet.sample(12).name == "sample-12"
    with pytest.raises(ValueError, match="no CUReT sample is named 'felt '"):
        curet.sample("felt ")
    with pytest.raises(ValueError, match="sample number 62 is not in the data; valid numbers are 1-61"):
        curet.sample(62)


@needs_data
def test_angle_order_option_swaps_source_and_viewer():
    swapped = read_curet(CURET_DIR, angle_order="illumination-first")
    default = read_curet(CURET_DIR)
    np.testing.assert_array_equal(swapped.theta_i, default.theta_r)
    np.testing.assert_array_equal(swapped.phi_r, default.phi_i)
    with pytest.raises(ValueError, match="angle_order = 'sideways'"):
        read_curet(CURET_DIR, angle_order="sideways")


@needs_data
def test_kvd_fit_reproduces_plaster_b_and_does_not_care_about_angle_order(curet):
    """Order-4 series (14 amplitudes) fitted to the 205 values of sample 11 (plaster_b):
    relative rms residual 0.031 measured (bound 0.035); the 41 held-out geometries are
    predicted to 0.036 relative rms (bound 0.045).  A reciprocal series gives the same
    fit whichever column order is assumed (1e-10: rounding of the solver)."""
    s = curet.sample("plaster_b")
    fit = kvd.fit_series(s.theta_i, s.phi_i, s.theta_r, s.phi_r, s.brdf, 4)
    assert fit.relative_rms_residual < 0.035
    swapped = kvd.fit_series(s.theta_r, s.phi_r, s.theta_i, s.phi_i, s.brdf, 4)
    np.testing.assert_allclose(swapped.coefficients.values, fit.coefficients.values, atol=1e-10)
    rng = np.random.default_rng(0)
    order = rng.permutation(205)
    test, train = order[:41], order[41:]
    partial = kvd.fit_series(s.theta_i[train], s.phi_i[train], s.theta_r[train], s.phi_r[train], s.brdf[train], 4)
    predicted = partial.coefficients.model()(s.theta_i[test], s.phi_i[test], s.theta_r[test], s.phi_r[test])
    held_out = np.sqrt(np.mean((predicted - s.brdf[test]) ** 2) / np.mean(s.brdf[test] ** 2))
    assert held_out < 0.045


@needs_data
def test_regularisation_helps_prediction_of_velvet_at_order_8(curet):
    """Velvet (sample 7), order 8 = 55 amplitudes from 164 samples: the plain fit
    overfits (held-out relative rms 0.163 measured), lam = 1e-5 sr^-2 halves it (0.090)."""
    s = curet.sample("velvet")
    rng = np.random.default_rng(0)
    order = rng.permutation(205)
    test, train = order[:41], order[41:]

    def held_out(lam):
        fit = kvd.fit_series(s.theta_i[train], s.phi_i[train], s.theta_r[train], s.phi_r[train], s.brdf[train], 8, regularization=lam)
        predicted = fit.coefficients.model()(s.theta_i[test], s.phi_i[test], s.theta_r[test], s.phi_r[test])
        return np.sqrt(np.mean((predicted - s.brdf[test]) ** 2) / np.mean(s.brdf[test] ** 2))

    assert held_out(1e-5) < 0.7 * held_out(0.0)


def write_pair(folder: Path, table: str, brdf: str) -> Path:
    (folder / "table.txt").write_text(table)
    (folder / "abrdf.dat").write_text(brdf)
    return folder


def test_small_files_round_trip_in_degrees(tmp_path):
    folder = write_pair(tmp_path, "1 0.5 1.0 0.25 -1.0\n2 0.0 0.0 1.0 3.0", "3 0.1 -0.02\n")
    data = read_curet(folder)
    np.testing.assert_allclose(data.theta_r, np.degrees([0.5, 0.0]))
    np.testing.assert_allclose(data.phi_i, np.degrees([-1.0, 3.0]))
    sample = data.sample(3)
    assert sample.negative.tolist() == [False, True] and sample.brdf[1] == -0.02


@pytest.mark.parametrize(
    "table, brdf, match",
    [
        ("1 0.5 1.0 0.25\n", "1 0.1\n", r"table.txt, line 1: expected 5 numbers"),
        ("1 0.5 1.0 0.25 x\n", "1 0.1\n", r"table.txt, line 1: expected 5 numbers .* got"),
        ("2 0.5 1.0 0.25 0.0\n", "1 0.1\n", r"table.txt, row 1: measurement index 2, expected 1"),
        ("1 2.0 1.0 0.25 0.0\n", "1 0.1\n", r"table.txt, row 1: polar angle theta_r = 114.592 deg"),
        ("1 0.5 1.0 0.25 0.0\n", "1 0.1 0.2\n", r"abrdf.dat, line 1: expected 2 numbers"),
        ("1 0.5 1.0 0.25 0.0\n", "1.5 0.1\n", r"abrdf.dat: the first column must hold distinct integer"),
        ("1 0.5 1.0 0.25 0.0\n", "1 nan\n", r"abrdf.dat, line 1: non-finite"),
    ],
)
def test_malformed_files_name_file_line_and_field(tmp_path, table, brdf, match):
    with pytest.raises(ValueError, match=match):
        read_curet(write_pair(tmp_path, table, brdf))


def test_missing_file_is_named(tmp_path):
    with pytest.raises(ValueError, match=r"table.txt: cannot read the CUReT"):
        read_curet_geometry(tmp_path / "table.txt")
    with pytest.raises(ValueError, match=r"abrdf.dat: cannot read"):
        read_curet_brdf(tmp_path / "abrdf.dat")

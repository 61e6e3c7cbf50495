"""``gonio reduce --brdf``: the calibrated BRDF table, its components and covariance
(gonio.reduction.brdf_table, docs/data-format.md "The calibrated BRDF table")."""
from __future__ import annotations

import json

import numpy as np
import pytest

from gonio import acquisition, protocols, reduction
from gonio.cli import main
from gonio.cli.run import emulated_rig
from gonio.fitting import Dataset

CALIBRATED = """
[protocol]
name = "calibrated"
[sample]
label = "matte"
mountings = 2
[reference]
label = "diffuse standard"
reflectance = 0.99
reflectance_uncertainty = 0.005
geometries = [[30, 0, -10], [60, 0, -10]]
[[block]]
theta_i = [30, 60]
view = [-50, -20, 0, 20, 45]
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A calibrated recording of a textured sample mounted twice on the default (realistic)
    rig: every covariance term (texture, mountings, PRNU, linearity, calibration) present."""
    tmp = tmp_path_factory.mktemp("brdf")
    protocol = protocols.loads(CALIBRATED, source="calibrated.toml")
    folder = tmp / "rec"
    with emulated_rig("oren-nayar:sigma=25,rho=0.8", 4, name="brdf-export") as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                 change_sample=lambda which, **how: change(which, 0.99, **how))
    return folder


def _header(path):
    header = {}
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        key, _, value = line[1:].partition(":")
        header[key.strip()] = json.loads(value)  # every header value is plain JSON
    return header


@pytest.mark.parametrize("calibration", ["common", "per-incidence"])
def test_brdf_csv_holds_the_calibrated_values_their_components_and_covariance(recording, tmp_path, calibration):
    out = tmp_path / "out"
    assert main(["reduce", str(recording), "--out", str(out), "--brdf", "--calibration", calibration]) == 0
    reduced = reduction.reduce_recording(recording)
    expected = reduced.brdf(calibration)
    header = _header(out / "brdf.csv")
    assert header["quantity"] == "brdf" and header["unit"] == "1/sr" and header["calibration"] == calibration
    assert header["covariance"] == "brdf_covariance.npy" and isinstance(header["calibration_budget"], dict)
    table = np.genfromtxt(out / "brdf.csv", delimiter=",", names=True, skip_header=len(header), dtype=None,
                          encoding="utf-8")
    np.testing.assert_array_equal(table["value"], expected.value)
    np.testing.assert_array_equal(table["sigma"], expected.sigma)
    # the components add in quadrature to the standard uncertainty
    components = np.array([table[name] for name in header["components"]])
    np.testing.assert_allclose(np.sqrt(np.sum(components**2, axis=0)), expected.sigma, rtol=1e-9)
    assert np.all(table["u_calibration"] > 0) and np.all(table["u_texture"] > 0)
    covariance = np.load(out / "brdf_covariance.npy")
    np.testing.assert_array_equal(covariance, expected.covariance)
    # read back as a dataset, the covariance comes with the table
    back = Dataset.from_csv(out / "brdf.csv")
    assert back.quantity == "brdf"
    np.testing.assert_array_equal(back.covariance, expected.covariance)
    np.testing.assert_array_equal(back.value, expected.value)


def test_the_manifest_covers_the_brdf_files_and_overwrite_replaces_the_whole_reduction(recording, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["reduce", str(recording), "--out", str(out), "--brdf"]) == 0
    assert reduction.is_whole_reduction(out)
    budget = json.loads((out / "budget.json").read_text())
    assert set(budget["files"]) == {"reduced.csv", "brdf.csv", "brdf_covariance.npy"}
    (out / "brdf.csv").write_text((out / "brdf.csv").read_text() + "1,2,3\n")
    assert not reduction.is_whole_reduction(out)  # a table edited by hand is not this reduction's
    assert main(["reduce", str(recording), "--out", str(out), "--overwrite"]) == 2
    (out / "brdf.csv").unlink()
    assert not reduction.is_whole_reduction(out)
    fresh = tmp_path / "fresh"
    assert main(["reduce", str(recording), "--out", str(fresh), "--brdf"]) == 0
    assert main(["reduce", str(recording), "--out", str(fresh), "--overwrite"]) == 0  # without --brdf
    assert not (fresh / "brdf.csv").exists() and not (fresh / "brdf_covariance.npy").exists()
    assert reduction.is_whole_reduction(fresh)


def test_brdf_without_a_reference_standard_is_refused_naming_why(tmp_path, capsys):
    text = CALIBRATED.replace("mountings = 2\n", "").split("[reference]")[0] + "[[block]]\ntheta_i = 30\nview = [0, 20]\n"
    protocol = protocols.loads(text, source="plain.toml")
    folder = tmp_path / "plain"
    with emulated_rig("lambert:rho=0.5", 1, name="brdf-plain", realism="ideal") as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now)
    assert main(["reduce", str(folder), "--out", str(tmp_path / "out"), "--brdf"]) == 2
    assert "needs the reference standard" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # nothing written

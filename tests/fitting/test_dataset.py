"""The data interface of the fits: Dataset validation, CSV form, incidence grouping."""
from __future__ import annotations

import numpy as np
import pytest

from gonio.fitting import Dataset


def _good(**changes):
    fields = dict(theta_i=30.0, phi_i=0.0, theta_r=[0.0, 20.0, 40.0], phi_r=[0.0, 0.0, 180.0],
                  value=[0.3, 0.29, 0.27], sigma=0.01)
    fields.update(changes)
    return Dataset(**fields)


def test_scalars_broadcast_to_one_entry_per_measurement():
    data = _good()
    assert data.n == 3
    assert data.theta_i.tolist() == [30.0, 30.0, 30.0]
    assert data.sigma.tolist() == [0.01, 0.01, 0.01]


@pytest.mark.parametrize(
    "field, value, fragment",
    [
        ("theta_r", [0.0, 20.0], "'theta_r' has 2 entries"),
        ("theta_r", [[0.0, 1.0, 2.0]], "'theta_r' must be one-dimensional"),
        ("value", [0.3, np.nan, 0.2], "'value' entry 1"),
        ("phi_r", [0.0, np.inf, 0.0], "'phi_r' entry 1"),
        ("sigma", [0.01, -0.01, 0.01], "'sigma' entry 1"),
        ("sigma", 0.0, "'sigma' entry 0"),
        ("theta_i", 95.0, "'theta_i' entry 0 = 95"),
        ("theta_r", [0.0, -5.0, 1.0], "'theta_r' entry 1 = -5"),
        ("quantity", "intensity", "'quantity'"),
        ("value", [], "'value' is empty"),
        ("value", ["a", "b", "c"], "'value' must be numeric"),
    ],
)
def test_bad_input_raises_value_error_naming_the_field(field, value, fragment):
    with pytest.raises(ValueError, match=fragment.replace("[", r"\[")):
        _good(**{field: value})


def test_arrays_are_read_only():
    data = _good()
    with pytest.raises(ValueError):
        data.value[0] = 1.0


def test_csv_round_trip_is_exact(tmp_path):
    data = _good(quantity="normalised_radiance", label="plaster", metadata={"instrument": "emulator"})
    back = Dataset.from_csv(data.to_csv(tmp_path / "d.csv"))
    for name in ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name))
    assert (back.quantity, back.label, back.metadata) == ("normalised_radiance", "plaster", {"instrument": "emulator"})


def test_csv_errors_name_file_line_and_column(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("theta_i,phi_i,theta_r,phi_r,value,sigma\n30,0,10,0,0.3,0.01\n30,0,20,0,oops,0.01\n")
    with pytest.raises(ValueError, match=r"bad.csv, line 3: column 'value' = 'oops'"):
        Dataset.from_csv(path)
    path.write_text("theta_i,phi_i,theta_r,value,sigma\n")
    with pytest.raises(ValueError, match=r"lacks the column\(s\) \['phi_r'\]"):
        Dataset.from_csv(path)
    path.write_text("theta_i,phi_i,theta_r,phi_r,value,sigma\n30,0,10,0,0.3,-1\n")
    with pytest.raises(ValueError, match=r"bad.csv: Dataset field 'sigma'"):
        Dataset.from_csv(path)


def test_incidences_group_sources_and_in_plane_flags():
    data = Dataset([30, 30, 45, 45, 0, 0], [0, 0, 0, 0, 0, 90], [10, 20, 10, 30, 10, 10], [0, 90, 180, 0, 0, 45],
                   np.ones(6), 0.1)
    sources, index = data.incidences()
    # Normal incidence has no azimuth: phi_i = 0 and 90 are the same source.
    assert sources.tolist() == [[0.0, 0.0], [30.0, 0.0], [45.0, 0.0]]
    assert index.tolist() == [1, 1, 2, 2, 0, 0]
    assert data.in_plane.tolist() == [True, False, True, True, True, False]
    # Signed viewing angle (DESIGN.md): + on the source side (phi_r = phi_i).
    assert data.signed_view[[0, 2]].tolist() == [10.0, -10.0]

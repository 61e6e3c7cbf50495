"""FitProblem's inner-loop path (vectors) agrees with its checked path (mappings)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitProblem
from gonio.geometry import in_plane_angles


def _normalised_minnaert_data() -> Dataset:
    geometry = in_plane_angles(np.repeat([30.0, 60.0], 9), np.tile(np.arange(-80.0, 81.0, 20.0), 2))
    value = gonio.brdf("minnaert", *geometry, rho=0.6, k=0.7)
    normal = gonio.brdf("minnaert", geometry[0], geometry[1], 0.0, geometry[1], rho=0.6, k=0.7)
    return Dataset(*geometry, value / normal, 0.01, quantity="normalised_radiance")


def test_vector_path_equals_mapping_path():
    """residuals/log_likelihood (unchecked model calls) match predict (checked calls)."""
    data = _normalised_minnaert_data()
    problem = FitProblem("minnaert", data)
    vector = np.array([0.5, 0.8])
    values = problem.values(vector)
    expected = (problem.predict(values) - data.value) / data.sigma
    # Identical arithmetic on both paths: equality to the last bit.
    np.testing.assert_array_equal(problem.residuals(vector), expected)
    chi2 = float(np.dot(expected, expected))
    log_l = -0.5 * chi2 - float(np.sum(np.log(data.sigma))) - 0.5 * data.n * math.log(2 * math.pi)
    assert problem.log_likelihood(vector) == pytest.approx(log_l, rel=1e-14)  # summation order only


@pytest.mark.parametrize("bad", [-0.5, math.nan])
def test_vector_path_rejects_out_of_range_values(bad):
    """A free model parameter outside its bounds raises ValueError naming it, as predict does."""
    problem = FitProblem("minnaert", _normalised_minnaert_data())
    vector = np.array([bad, 0.8])  # rho in [0, 1]
    with pytest.raises(ValueError, match="rho"):
        problem.residuals(vector)
    with pytest.raises(ValueError, match="rho"):
        problem.log_likelihood(vector)
    with pytest.raises(ValueError, match="rho"):
        problem.predict(problem.values(vector))

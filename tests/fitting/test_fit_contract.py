"""Every registered model, with every subset of its parameters free, fits without a fault.

A fit is a contract with whoever calls it: whatever a model's parameters and ranges (a
refractive index on (1, inf), a series coefficient on the whole line, an exponent up to
1e4), least squares starts inside the ranges, stays inside them and returns a finite
chi-square. The subsets run over ``gonio.models.available()``, so a model registered later
is checked without anyone writing a test for it.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitProblem, fit_least_squares
from gonio.fitting.problem import predict_quantity

from .synthetic import in_plane_geometry

NAMES = gonio.models.available()
#: Few geometries keep the slow models (the exact V-cavity integral) quick.
GEOMETRY = in_plane_geometry(incidences=(30.0, 60.0), views=np.arange(-70.0, 71.0, 20.0))


def _dataset(name: str, quantity: str) -> Dataset:
    """The model at its defaults as ``quantity`` (radiance: times a scale of 1000, which the
    fit takes free) with 1 % noise and a floor of 1e-3 of the largest value."""
    values = predict_quantity(name, quantity, *GEOMETRY, {"scale": 1000.0})
    sigma = 0.01 * np.abs(values) + 1e-3 * float(np.max(np.abs(values)) or 1.0)
    noisy = values + sigma * np.random.default_rng(7).standard_normal(values.shape)
    return Dataset(*GEOMETRY, noisy, sigma, quantity=quantity)


@pytest.mark.parametrize("quantity", ["brdf", "radiance"])
@pytest.mark.parametrize("name", NAMES)
def test_every_subset_of_parameters_fits_inside_its_ranges(name, quantity):
    """With a free scale (radiance) the first evaluation is at every random start: a start
    outside a range stopped the fit there ("n = 0.42 outside (1, inf)")."""
    model = gonio.models.get(name)
    data = _dataset(name, quantity)
    names = [p.name for p in model.params]
    for size in range(1, len(names) + 1):
        for free in itertools.combinations(names, size):
            fixed = {p.name: p.default for p in model.params if p.name not in free}
            problem = FitProblem(name, data, fixed)
            result = fit_least_squares(problem, n_starts=3, seed=0)
            assert math.isfinite(result.chi2), (name, free)
            for parameter in free:
                spec = problem.spec(parameter)
                assert spec.contains(result.values[parameter]), (name, free, parameter, result.values[parameter])

"""benchmarks/validity_fits.py: one fit of a cell on a tiny case (truth on sigma's bound,
where every estimate of sigma lies above the truth) and the counting of coverage and bias
over a cell's records."""
from __future__ import annotations

import math

import pytest

from tests.conftest import benchmark_script



@pytest.fixture(scope="module")
def study():
    return benchmark_script("validity_fits")


def test_truth_on_the_bound_is_outside_every_central_interval_and_under_the_upper_limit(study):
    settings = {**study.BASE, "sigma": 0.0, "points": 8}
    record = study.run_fit(settings, seed=3, max_steps=300)
    assert record["truth"] == {"rho": study.RHO, "sigma": 0.0}
    mcmc = record["intervals"]["MCMC"]["sigma"]
    # sigma >= 0: the posterior median lies above the truth 0, so the bias is positive, and a
    # central 95 % interval of a posterior on (0, 90] cannot hold 0
    assert mcmc["point"] > 0.0 and mcmc["z"] > 0.0
    assert mcmc["covered"] is False and mcmc["below_upper"] is True
    assert 0.0 < mcmc["lo"] < mcmc["point"] < mcmc["hi"]
    laplace = record["intervals"]["Laplace"]["sigma"]
    if laplace["covered"] is not None:  # truncated to [0, 90]: a median above 0
        assert laplace["lo"] >= 0.0 and laplace["z"] > 0.0
    rho = record["intervals"]["MCMC"]["rho"]
    assert rho["covered"] == (rho["lo"] <= study.RHO <= rho["hi"])
    assert math.isclose(rho["z"], (rho["point"] - study.RHO) / rho["sd"])
    assert record["sampler"]["steps"] <= 300


def _record(study, seed: int, lo: float, hi: float, point: float, sd: float = 1.0, converged: bool = True):
    truth = {"sigma": 10.0, "rho": 0.8}
    intervals = {method: {"sigma": study._interval(point, lo, hi, sd, truth["sigma"], sd),
                          "rho": study._interval(0.8, 0.79, 0.81, 0.005, truth["rho"], 0.005)}
                 for method in study.METHODS}
    intervals["least squares"]["sigma"] = study._interval(math.nan, math.nan, math.nan, math.nan, 10.0, sd)
    flags = [] if converged else ["CHAIN NOT CONVERGED: 300 steps reached the limit"]
    return {"cell": "c", "settings": {}, "seed": seed, "max_steps": 300, "truth": truth, "free": ["rho", "sigma"],
            "intervals": intervals, "posterior_correlation": {"rho-sigma": 0.5},
            "sampler": {"steps": 100 * (seed + 1), "converged": converged, "acceptance": 0.3, "tau_max": 5.0,
                        "rhat_max": 1.0}, "flags": flags, "verdict": "adequate", "seconds": 1.0}


def test_coverage_bias_and_failures_are_counted_per_method(study):
    records = [_record(study, 0, 9.0, 11.0, 10.5), _record(study, 1, 10.5, 12.0, 11.0),
               _record(study, 2, 8.0, 12.0, 9.0), _record(study, 3, 11.0, 13.0, 12.0, converged=False)]
    cell = study.summarise_cell(records)
    mcmc = cell["params"]["sigma"]["MCMC"]
    assert (mcmc["covered"], mcmc["with_interval"]) == (2, 4)
    assert mcmc["coverage"] == 0.5
    assert mcmc["wilson"][0] < 0.5 < mcmc["wilson"][1]
    assert mcmc["upper_limit_coverage"] == 1.0
    assert math.isclose(mcmc["bias_sd"], (0.5 + 1.0 - 1.0 + 2.0) / 4)  # points minus truth 10, sd 1
    assert cell["params"]["sigma"]["least squares"]["with_interval"] == 0
    assert cell["params"]["sigma"]["least squares"]["coverage"] is None
    assert cell["params"]["sigma"]["ls_undetermined"] == 1.0
    assert cell["params"]["rho"]["Laplace"]["coverage"] == 1.0
    assert cell["sampler"]["failed"] == 1 and cell["sampler"]["failure_rate"] == 0.25
    assert cell["warnings"] == {"not converged": 1}

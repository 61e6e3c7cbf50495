"""Proper priors: normalisation, support, parsing and round trips."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from gonio.fitting.priors import LogUniform, Normal, Uniform, default_prior, parse_prior, prior_from_dict


@pytest.mark.parametrize("prior", [Uniform(0.0, 1.0), LogUniform(0.01, 100.0), Normal(30.0, 10.0, 0.0, 90.0)])
def test_priors_are_normalised(prior):
    # A proper prior integrates to 1 over its support; quad is accurate to ~1e-8 here.
    total, _ = integrate.quad(lambda x: math.exp(prior.logpdf(x)), prior.lower, prior.upper, limit=200,
                              points=[getattr(prior, "mean", prior.lower)])
    assert total == pytest.approx(1.0, abs=1e-6)
    assert prior.logpdf(prior.lower - 1.0) == -math.inf


def test_samples_stay_in_the_support():
    rng = np.random.default_rng(0)
    for prior in (Uniform(0, 1), LogUniform(1, 10), Normal(0.0, 5.0, 0.0, 1.0)):
        draws = prior.sample(rng, 500)
        assert draws.min() >= prior.lower and draws.max() <= prior.upper


def test_default_priors_follow_the_bounds():
    assert default_prior("rho", (0.0, 1.0), 0.5) == Uniform(0.0, 1.0)
    # Unbounded positive parameter: log-uniform over six decades around the reference.
    assert default_prior("scale", (0.0, math.inf), 2.0) == LogUniform(0.002, 2000.0)


def test_parse_and_round_trip():
    prior = parse_prior("uniform:-5:200", (0.0, 90.0))
    assert prior == Uniform(0.0, 90.0)  # intersected with the physical range
    for prior in (Uniform(0, 1), LogUniform(1, 10), Normal(30, 5, 0, 90)):
        assert prior_from_dict(prior.to_dict()) == prior
    with pytest.raises(ValueError, match="unknown kind 'beta'"):
        parse_prior("beta:1:2")
    with pytest.raises(ValueError, match="expected uniform:LO:HI"):
        parse_prior("uniform:1")


def test_truncated_normal_with_open_side_round_trips_through_strict_json():
    """A calibration prior N(E0, sd) on [0, inf) is saved with upper = null (strict JSON)."""
    import json
    import math

    from gonio.fitting.priors import Normal, prior_from_dict
    from gonio.fitting.results import _clean

    prior = Normal(2.0e5, 300.0, 0.0, math.inf)
    text = json.dumps(_clean(prior.to_dict()), allow_nan=False)
    back = prior_from_dict(json.loads(text))
    assert back.upper == math.inf and back.mean == prior.mean and back.sd == prior.sd


def test_quantile_inverts_each_prior_s_distribution():
    """Prior.quantile maps u in [0, 1] to the point below which the prior holds u (checked by
    quadrature of its density), tails included: the unit cube the evidence sampler uses."""
    import math

    from scipy.integrate import quad

    from gonio.fitting.priors import LogUniform, Normal, Uniform

    for prior in (Uniform(0.0, 90.0), LogUniform(0.1, 1.0e5), Normal(100.0, 2.0, 0.0, math.inf),
                  Normal(0.5, 0.1, 0.6, 1.0), Normal(0.0, 0.5, -5.0, 5.0)):
        start = prior.lower if math.isfinite(prior.lower) else -60.0
        for u in (1e-6, 0.01, 0.3, 0.5, 0.97, 1 - 1e-6):
            x = float(prior.quantile(u))
            below = quad(lambda t: math.exp(prior.logpdf(t)), start, x, limit=200, epsabs=1e-13)[0]
            assert below == pytest.approx(u, abs=1e-9), (prior, u)
        assert prior.quantile(0.0) == pytest.approx(prior.lower) or not math.isfinite(prior.lower)

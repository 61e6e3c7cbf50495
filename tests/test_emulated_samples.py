"""The emulated sample's model is evaluated at the accuracy gonio.cli.samples sets for it."""
from __future__ import annotations

import numpy as np

import gonio
from gonio.cli.samples import SAMPLE_MODEL_OPTIONS, parse_sample_spec


def test_an_exact_sample_is_evaluated_well_below_the_ideal_rigs_noise():
    sample = parse_sample_spec("oren-nayar-exact:rho=0.9,sigma=30")
    assert sample.brdf.keywords["rtol"] == SAMPLE_MODEL_OPTIONS["oren-nayar-exact"]["rtol"]
    rng = np.random.default_rng(3)
    ti, tr, pr = rng.uniform(0, 85, 60), rng.uniform(0, 85, 60), rng.uniform(-180, 180, 60)
    tight = gonio.brdf("oren-nayar-exact", ti, 0.0, tr, pr, rho=0.9, sigma=30.0, rtol=1e-7)
    # a tenth of the ideal rig's 6e-5 relative uncertainty per value
    assert np.max(np.abs(sample.brdf(ti, 0.0, tr, pr) / tight - 1.0)) < 6e-6


def test_a_spec_s_own_accuracy_wins_and_is_not_a_parameter():
    sample = parse_sample_spec("oren-nayar-exact:rho=0.9,sigma=30,rtol=1e-7")
    assert sample.brdf.keywords["rtol"] == 1e-7
    assert "rtol" not in parse_sample_spec("oren-nayar-exact:rho=0.9,sigma=30").parameters

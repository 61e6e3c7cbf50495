"""benchmarks/calibration_paired.py: pairing of two coverage runs by (arm, seed), the
posterior shift and spread ratio against the Monte Carlo error it quotes beside them, and
the verdict changes (docs/calibration.md, "The same seeds under both samplers")."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from tests.conftest import benchmark_script



@pytest.fixture(scope="module")
def paired():
    return benchmark_script("calibration_paired")


def record(seed: int, median: float, sd: float, ess: float, *, arm: str = "closed-form", in68: bool = True,
           ls_value: float = 0.5) -> dict:
    param = {"median": median, "sd": sd, "ls_value": ls_value, "ls_stderr": 0.01, "in68": in68, "in95": True,
             "rank": 50, "z": 0.0}
    return {"arm": arm, "seed": seed, "ess_min": ess, "n_steps": 1000, "n_samples": 4000, "tau_max": 10.0,
            "params": {"rho": dict(param), "sigma": dict(param)}}


def test_pairs_by_arm_and_seed_and_drops_unmatched(paired):
    before = {"coverage_records": [record(1, 0.5, 0.01, 1e3), record(2, 0.5, 0.01, 1e3),
                                   record(1, 0.5, 0.01, 1e3, arm="tabulated")]}
    after = {"coverage_records": [record(2, 0.6, 0.01, 1e3), record(1, 0.7, 0.01, 1e3), record(3, 0.5, 0.01, 1e3)]}
    pairs = paired.paired_records(before, after)
    assert set(pairs) == {"closed-form"}  # the tabulated seed and seed 3 have no partner
    assert [(b["seed"], a["params"]["rho"]["median"]) for b, a in pairs["closed-form"]] == [(1, 0.7), (2, 0.6)]


def test_shift_ratio_and_verdicts_of_a_known_change(paired):
    before = [record(s, 0.5, 0.01, 1e3, in68=True) for s in range(4)]
    after = [record(s, 0.5 + 0.005, 0.02, 1e3, in68=(s != 0), ls_value=0.5 + 1e-4) for s in range(4)]
    out = paired.compare_parameter(list(zip(before, after)), "rho")
    # exact arithmetic on exact inputs: every median moved by half an sd, every sd doubled
    assert out["median_shift_over_sd"]["mean"] == pytest.approx(0.5, rel=1e-12)
    assert out["median_shift_over_sd"]["rms"] == pytest.approx(0.5, rel=1e-12)
    assert out["sd_ratio"]["median"] == pytest.approx(2.0, rel=1e-12)
    assert out["sd_ratio"]["log_rms"] == pytest.approx(math.log(2.0), rel=1e-12)
    assert out["least_squares_shift_over_stderr_max_abs"] == pytest.approx(0.01, rel=1e-9)
    assert out["verdict_changes"] == {"68": 1, "95": 0}
    assert out["coverage"]["68"] == [4, 3]
    # module docstring: sqrt(pi/2) sqrt(1/N1 + 1/N2) and sqrt(1/(2 N1) + 1/(2 N2))
    assert out["median_shift_over_sd"]["rms_expected_from_ess"] == pytest.approx(math.sqrt(math.pi / 2 * 2e-3))
    assert out["sd_ratio"]["log_rms_expected_from_ess"] == pytest.approx(math.sqrt(1e-3))


def test_monte_carlo_error_it_quotes_is_the_scatter_of_two_independent_chains(paired):
    """Two sets of N independent draws of the same N(0, 1) posterior per seed (ESS = N):
    the quoted Monte Carlo error must be the observed rms of the shift and of log(sd ratio)."""
    rng = np.random.default_rng(7)
    n_draws, n_seeds = 400, 1500
    first, second = rng.standard_normal((2, n_seeds, n_draws))
    pairs = [(record(s, float(np.median(a)), float(np.std(a, ddof=1)), n_draws),
              record(s, float(np.median(b)), float(np.std(b, ddof=1)), n_draws))
             for s, (a, b) in enumerate(zip(first, second))]
    out = paired.compare_parameter(pairs, "rho")
    # an rms over 1500 seeds has a relative sd of about 1/sqrt(2 x 1500) = 1.8 %; the
    # median's asymptotic error is good to ~1 % at N = 400; 7 % is about 4 such sds
    shift = out["median_shift_over_sd"]
    assert shift["rms"] == pytest.approx(shift["rms_expected_from_ess"], rel=0.07)
    ratio = out["sd_ratio"]
    assert ratio["log_rms"] == pytest.approx(ratio["log_rms_expected_from_ess"], rel=0.07)


def test_gaussian_pit_and_ranks_fill_the_bins_they_should(paired):
    """One seed per tenth: Phi(-z) = 0.05, 0.15, ..., 0.95 and ranks 5, 15, ..., 95 of 0..99."""
    records = []
    for k in range(10):
        r = record(k, 0.5, 0.01, 1e3)
        r["params"]["rho"]["z"] = -float(stats.norm.ppf((k + 0.5) / 10))
        r["params"]["rho"]["rank"] = 10 * k + 5
        records.append(r)
    out = paired.uniformity(records, "rho", draws=99, bins=10)
    assert out["pit_counts"] == [1] * 10
    assert out["rank_counts"] == [1] * 10
    assert out["pit_chi2_p"] == pytest.approx(1.0)
    assert out["rank_pit_correlation"] == pytest.approx(1.0, abs=1e-6)  # both are the same ordering, evenly spaced


def test_unknown_source_is_a_clear_error(paired):
    with pytest.raises(ValueError, match="neither a file nor a git revision"):
        paired.load_calibration("no-such-revision-or-file")


def test_runs_of_different_studies_are_refused(paired, tmp_path):
    design = {"prior": {"rho": [0.5, 0.95]}, "sbc_draws": 99, "rank_bins": 10, "mcmc": "stretch"}
    runs = {"same.json": {**design, "mcmc": "de"}, "other.json": {**design, "prior": {"rho": [0.1, 0.9]}}}
    for name, run_design in runs.items():
        (tmp_path / name).write_text(json.dumps(
            {"design": run_design, "git": {"commit": "x"}, "coverage_records": [record(1, 0.5, 0.01, 1e3)]}))
    before = {"design": design}
    assert paired.design_differences(before, {"design": runs["same.json"]}) == []  # only the MCMC differs
    assert paired.design_differences(before, {"design": runs["other.json"]}) == ["prior"]
    with pytest.raises(SystemExit, match="different studies.*prior"):
        paired.main(["--before", str(tmp_path / "same.json"), "--after", str(tmp_path / "other.json")])

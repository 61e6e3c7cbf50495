"""A fit runs with one BLAS thread whatever its caller set (gonio.fitting.fit's
``blas_threads``; docs/fitting.md, "Performance")."""
from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import gonio
from gonio.fitting import Dataset, fit
from gonio.fitting import workflow


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


@pytest.fixture
def seen_during_sampling(monkeypatch):
    """The BLAS thread counts the MCMC sampler runs with, recorded at each call."""
    seen = []
    original = workflow.sample_posterior

    def recording(*args, **kwargs):
        seen.append(_blas_threads())
        return original(*args, **kwargs)

    monkeypatch.setattr(workflow, "sample_posterior", recording)
    return seen


def _data() -> Dataset:
    theta_r = np.arange(0.0, 80.0, 5.0)
    value = gonio.brdf("lambert", 30.0, 0.0, theta_r, 0.0, rho=0.5)
    return Dataset(30.0, 0.0, theta_r, 0.0, value, 0.01 * value)


def test_the_sampler_runs_with_one_blas_thread_whatever_the_caller_set(seen_during_sampling):
    if not _blas_threads():
        pytest.skip("no BLAS library that threadpoolctl can control")
    with threadpool_limits(limits=2, user_api="blas"):
        assert set(_blas_threads()) == {2}
        fit(_data(), "lambert", seed=1, max_steps=2000)
        assert set(_blas_threads()) == {2}  # the caller's setting is back afterwards
    assert seen_during_sampling and set(seen_during_sampling[0]) == {1}


def test_blas_threads_none_leaves_the_callers_setting(seen_during_sampling):
    if not _blas_threads():
        pytest.skip("no BLAS library that threadpoolctl can control")
    with threadpool_limits(limits=2, user_api="blas"):
        fit(_data(), "lambert", seed=1, max_steps=2000, blas_threads=None)
    assert set(seen_during_sampling[0]) == {2}

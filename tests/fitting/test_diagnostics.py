"""ArviZ's diagnostics without importing ArviZ's xarray layer, and posterior.nc without ArviZ."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from gonio.fitting.diagnostics import convergence_diagnostics, inference_data
from gonio.fitting.inference_file import write_inference_data


def _arviz():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz

    return arviz


def _slow_chain(seed: int) -> np.ndarray:
    """(steps, walkers, parameters): random walks plus noise, R-hat well above 1."""
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=(300, 12, 3)), axis=0) * 0.05 + rng.normal(size=(300, 12, 3))


def test_diagnostics_equal_arvizs_rhat_and_ess():
    # Same algorithm: equal to rounding (arviz 0.x may sum variances in a numba loop, a
    # different order than numpy's; 1e-12 relative). A different method would differ in
    # the second digit (tail ESS at other quantiles, R-hat not rank-normalised or split).
    az = _arviz()
    chain = _slow_chain(1)
    ours = convergence_diagnostics(chain, ["a", "b", "c"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        data = az.convert_to_dataset({n: chain[:, :, k].T for k, n in enumerate("abc")})
    r_hat, bulk, tail = az.rhat(data, method="rank"), az.ess(data, method="bulk"), az.ess(data, method="tail")
    for n in "abc":
        assert ours[n]["r_hat"] == pytest.approx(float(r_hat[n]), rel=1e-12) and ours[n]["r_hat"] > 1.05
        assert ours[n]["ess_bulk"] == pytest.approx(float(bulk[n]), rel=1e-12)
        assert ours[n]["ess_tail"] == pytest.approx(float(tail[n]), rel=1e-12)


_PROBE = """
import json, sys
{before}
had = {{name: id(module) for name, module in sys.modules.items() if name.split('.')[0] in ('xarray', 'arviz_stats')}}
from gonio.fitting.diagnostics import array_stats
stats = array_stats()
import numpy as np
r_hat = float(stats.rhat(np.random.default_rng(0).normal(size=(4, 100)), method='rank'))
after = {{name: id(module) for name, module in sys.modules.items() if name.split('.')[0] in ('xarray', 'arviz_stats')}}
print(json.dumps({{"kept": all(after.get(name) == ident for name, ident in had.items()),
                  "added": sorted(set(after) - set(had)), "xarray": 'xarray' in sys.modules, "pandas": 'pandas' in sys.modules,
                  "r_hat": r_hat}}))
"""


@pytest.mark.parametrize("before", ["", "import xarray", "import arviz_stats"])
def test_array_stats_leaves_the_modules_as_they_were(before):
    """Loading ArviZ's numpy core with xarray hidden leaves xarray and arviz_stats in
    sys.modules as they were (a fresh interpreter per case): nothing imported before is
    replaced, and without a previous ``import arviz_stats`` none of its modules stays (a
    later import gets the whole package). After the user's own ``import arviz_stats``,
    its numpy core is imported as a submodule of that package, as any import would."""
    out = subprocess.run([sys.executable, "-c", _PROBE.format(before=before)], check=True, capture_output=True,
                         text=True)
    probe = json.loads(out.stdout.strip().splitlines()[-1])
    assert probe["kept"]
    if before != "import arviz_stats":
        assert probe["added"] == []
    assert probe["xarray"] == (before != "")  # arviz_stats imports xarray when imported by the user
    if before == "":
        assert not probe["pandas"]
    assert 0.9 < probe["r_hat"] < 1.1


def test_posterior_file_reads_back_as_arvizs_inference_data(tmp_path):
    az = _arviz()
    rng = np.random.default_rng(3)
    args = (rng.normal(size=(40, 6, 2)), rng.normal(size=(40, 6)), ["rho", "sigma"], rng.normal(size=(40, 6, 5)),
            rng.normal(size=5), {"model": "oren-nayar", "quantity": "brdf", "gonio_version": "1"})
    extra = {"predictive": rng.normal(size=(10, 6, 5)),
             "geometry": {"theta_i": rng.uniform(0, 80, 5), "theta_r": rng.uniform(0, 80, 5)}}
    (tmp_path / "posterior.nc").write_bytes(write_inference_data(*args, **extra))
    got = az.from_netcdf(tmp_path / "posterior.nc")
    expected = inference_data(*args, **extra)
    assert set(got.groups()) == set(expected.groups()) == {"posterior", "sample_stats", "log_likelihood",
                                                           "posterior_predictive", "observed_data", "constant_data"}
    for group in expected.groups():
        assert got[group].equals(expected[group]), group  # values, dimensions, coordinates
        dimension = "chain" if group not in ("observed_data", "constant_data") else "y_dim_0"
        assert got[group][dimension].dtype == np.int64
    for key in ("model", "quantity", "gonio_version"):
        assert got.posterior.attrs[key] == expected.posterior.attrs[key]
    np.testing.assert_array_equal(got.posterior["sigma"].values, args[0][:, :, 1].T)

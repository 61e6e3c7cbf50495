"""The Bayesian fit against the plain emcee baseline on a problem with grazing points.

``benchmarks/bench_fitting.py`` times the fit at the Fig 16 incidences (30, 45, 60 deg),
where the functional model's linear form is exact at every point. Add theta_i = 75 deg and
eq 33's floor can act at some views: the linear form is not exact there. The fast
likelihood once turned off for the whole dataset at such a point; it now takes those
points with the model itself and the rest through the sufficient statistics
(``gonio.fitting.problem.FloorPoints``). This script measures that, in one run:

* the plain emcee baseline of bench_fitting.py (least squares, stretch move, numpy
  log-probability vectorised over 32 walkers, 50-tau rule);
* ``gonio.fitting.fit`` with its defaults;
* the same fit with the linear path turned off (every walker through the model at every
  point, the state before the point-by-point path);
* a compiled differential-evolution sampler (ter Braak 2006; benchmarks/_compiled_de.py):
  the whole loop, model and likelihood in one numba function, 32 walkers from the same
  least-squares start, 4000 generations, ESS from its chain after 2 tau. The target: gonio
  at least a quarter of its ESS per second.

Problem: Oren-Nayar (rho 0.9, sigma 30 deg, ir_weight 1) at theta_i = 30, 45, 60, 75 deg,
67 views from -80 to 80 deg (268 values), 1 % noise. Medians of 3 seeds, ESS of sigma per
second of MCMC (ArviZ bulk after 2 tau), as bench_fitting.py computes them.

Writes docs/benchmarks/fitting_grazing.json. Run: ``python benchmarks/bench_fitting_grazing.py``.
"""
from __future__ import annotations

import time
from unittest import mock

import numpy as np

import emcee

from _common import write_json
from _compiled_de import de_mcmc
from bench_fitting import FIXED, MODEL, TRUTH, _summary, median_record, plain_emcee_baseline

from gonio.fitting import Dataset, FitProblem, fit
from gonio.fitting.diagnostics import arviz
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

INCIDENCES = (30.0, 45.0, 60.0, 75.0)
SEEDS = (1, 2, 3)


def grazing_dataset() -> Dataset:
    """268 BRDF values at theta_i 30-75 deg, 1 % noise (seed 75)."""
    views = np.linspace(-80.0, 80.0, 67)
    geometry = in_plane_angles(np.repeat(INCIDENCES, views.size), np.tile(views, len(INCIDENCES)))
    exact = predict_quantity(MODEL, "brdf", *geometry, {**TRUTH, **FIXED})
    rng = np.random.default_rng(75)
    return Dataset(*geometry, exact * (1 + 0.01 * rng.standard_normal(exact.shape)), 0.01 * exact,
                   label="synthetic oren-nayar with grazing incidence")


def gonio_run(data: Dataset, seed: int, linear: bool) -> dict:
    """``fit`` with its defaults; ``linear=False`` turns the sufficient statistics off."""
    patch = (mock.patch.object(FitProblem, "_quadratic_chi_square", lambda self: None) if not linear
             else mock.patch.object(FitProblem, "_quadratic_chi_square", FitProblem._quadratic_chi_square))
    with patch:
        began = time.perf_counter()
        result = fit(data, MODEL, fixed=FIXED, max_steps=40000, seed=seed)
        total = time.perf_counter() - began
    m = result.mcmc
    name = "gonio" if linear else "gonio, linear path off"
    return _summary(name, m.chain, m.tau, m.wall_seconds, total - m.wall_seconds, m.n_walkers,
                    converged=bool(m.converged))


def compiled_de_run(data: Dataset, seed: int, steps: int = 4000) -> dict:
    """The compiled DE-MC reference from gonio's least-squares optimum (compiled before timing)."""
    from gonio.fitting import fit_least_squares

    problem = FitProblem(MODEL, data, FIXED)
    optimum = fit_least_squares(problem).values
    centre = np.array([optimum["rho"], optimum["sigma"]])
    rng = np.random.default_rng(seed)
    start = centre * (1 + 1e-3 * rng.standard_normal((32, 2)))
    angles = (np.radians(data.theta_i), np.radians(data.theta_r), np.radians(data.phi_r - data.phi_i))
    de_mcmc(start, 10, seed, *angles, data.value, data.sigma)  # compiled (or read from the cache) here
    began = time.perf_counter()
    chain = de_mcmc(start, steps, seed, *angles, data.value, data.sigma)
    wall = time.perf_counter() - began
    tau = emcee.autocorr.integrated_time(chain, tol=0)
    return _summary("compiled DE-MC", chain, tau, wall, 0.0, 32)


def main() -> None:
    data = grazing_dataset()
    problem = FitProblem(MODEL, data, FIXED)
    floor_points = int(np.sum(~np.asarray(problem._fast.linear_form().exact)))
    arviz()
    runs = {"baseline": [], "gonio": [], "gonio_linear_off": [], "compiled_de": []}
    for seed in SEEDS:  # interleaved: a change of load hits every method alike
        runs["compiled_de"].append(compiled_de_run(data, seed))
        runs["baseline"].append(plain_emcee_baseline(data, seed))
        runs["gonio"].append(gonio_run(data, seed, True))
        runs["gonio_linear_off"].append(gonio_run(data, seed, False))
        print(f"seed {seed}: " + ", ".join(f"{k} {v[-1]['ess_sigma_per_s']:.0f} ESS/s" for k, v in runs.items()),
              flush=True)
    medians = {name: median_record(r) for name, r in runs.items()}
    base = medians["baseline"]["ess_sigma_per_s"]
    record = {"command": "python benchmarks/bench_fitting_grazing.py", "n_data": data.n,
              "points_where_the_floor_can_act": floor_points, "medians": medians,
              "speedup_over_baseline": {k: v["ess_sigma_per_s"] / base for k, v in medians.items()},
              "target_speedup": 5.0,
              "gonio_over_compiled_de": medians["gonio"]["ess_sigma_per_s"] / medians["compiled_de"]["ess_sigma_per_s"],
              "target_over_compiled_de": 0.25, "runs": runs}
    write_json("fitting_grazing", record)
    for name, ratio in record["speedup_over_baseline"].items():
        print(f"{name}: {medians[name]['ess_sigma_per_s']:.0f} ESS/s of sigma, x{ratio:.1f} the baseline, "
              f"MCMC {medians[name]['mcmc_wall_s']:.2f} s")
    print(f"gonio / compiled DE-MC: {record['gonio_over_compiled_de']:.2f}")


if __name__ == "__main__":
    main()

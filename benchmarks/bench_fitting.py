"""Speed of the Bayesian fit against a plain emcee baseline, measured in one run.

The problem (issue "Fast inference"): Oren-Nayar (rho = 0.9, sigma = 30 deg, interreflection
weight fixed at 1) fitted to 201 BRDF values in the plane of incidence at theta_i = 30,
45, 60 deg (the incidences of Oren & Nayar 1995, Fig 16; 67 views from -80 to 80 deg),
1 % noise; 2 free parameters.

* **Plain emcee baseline** (what a user writes in an afternoon): scipy least squares,
  then emcee's default stretch move with a numpy log-probability vectorised over 32
  walkers (``vectorize=True``), uniform priors, stopped by the emcee tutorial's rule
  (every 100 steps: chain > 50 tau and tau changed by < 5 %).  Its Oren-Nayar formula is
  written here from eq 33-35, independently of gonio's (their predictions are compared).
* **gonio**: ``gonio.fitting.fit`` with its defaults (emcee's differential-evolution move
  in gonio's loop, every walker of a half-ensemble in one model evaluation, 50 tau with a
  stable tau and R-hat < 1.01), for several ensemble sizes (benchmarks/bench_moves.py
  compares the moves and chooses the default ensemble).

For every run: MCMC wall time, effective samples of sigma per second (ESS computed the same
way for both: ArviZ bulk ESS of the chain after a burn-in of 2 tau), the posterior median
and sd of sigma, and the agreement with the baseline's posterior (|median difference| /
sd, sd ratio).  Also measured: one likelihood evaluation through the fixed-geometry path
against the plain path, least squares, and the fit ``gonio demo`` makes on emulated rig
data (:func:`emulator_demo_fit`).

Writes docs/benchmarks/fitting.json and docs/benchmarks/fitting.png.
Run: ``python benchmarks/bench_fitting.py``.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import emcee
import numpy as np
from scipy.optimize import least_squares

import gonio
from gonio.fitting import Dataset, FitProblem, fit, fit_least_squares
from gonio.fitting.diagnostics import arviz
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine  # noqa: E402

MODEL, TRUTH, FIXED = "oren-nayar", {"rho": 0.9, "sigma": 30.0}, {"ir_weight": 1.0}
#: Ensemble sizes of gonio's runs (the default is chosen from these).
WALKERS = (16, 24, 32, 64, 128, 256)
#: Seeds of each configuration (medians are reported).
SEEDS = (1, 2, 3)


def benchmark_dataset() -> Dataset:
    """201 BRDF values of Oren-Nayar at the Fig 16 incidences, 1 % noise (seed 16)."""
    views = np.linspace(-80.0, 80.0, 67)
    geometry = in_plane_angles(np.repeat([30.0, 45.0, 60.0], views.size), np.tile(views, 3))
    exact = predict_quantity(MODEL, "brdf", *geometry, {**TRUTH, **FIXED})
    rng = np.random.default_rng(16)
    return Dataset(*geometry, exact * (1 + 0.01 * rng.standard_normal(exact.shape)), 0.01 * exact,
                   label="synthetic oren-nayar, Oren & Nayar Fig 16 incidences")


def plain_oren_nayar(theta_i, phi_i, theta_r, phi_r, rho, sigma):
    """Oren & Nayar (1995) eq 33-35 with w = 1, angles [deg], rho and sigma of shape (W, 1):
    the baseline's own formula, as a user would type it from the paper."""
    ti, tr, dphi = np.radians(theta_i), np.radians(theta_r), np.radians(phi_r - phi_i)
    s2 = np.radians(sigma) ** 2
    alpha, beta, cos = np.maximum(ti, tr), np.minimum(ti, tr), np.cos(dphi)
    c1 = 1 - 0.5 * s2 / (s2 + 0.33)
    c2 = 0.45 * s2 / (s2 + 0.09) * np.where(cos >= 0, np.sin(alpha), np.sin(alpha) - (2 * beta / np.pi) ** 3)
    c3 = 0.125 * s2 / (s2 + 0.09) * (4 * alpha * beta / np.pi**2) ** 2
    direct = rho / np.pi * (c1 + cos * c2 * np.tan(beta) + (1 - np.abs(cos)) * c3 * np.tan((alpha + beta) / 2))
    inter = 0.17 * rho**2 / np.pi * s2 / (s2 + 0.13) * (1 - cos * (2 * beta / np.pi) ** 2)
    return np.maximum(direct + inter, 0.0)


def plain_emcee_baseline(data: Dataset, seed: int, n_walkers: int = 32) -> dict:
    """Least squares, then emcee (stretch move, vectorised log-probability), 50-tau rule."""
    geometry, value, sigma = data.geometry, data.value, data.sigma

    def log_prob(theta: np.ndarray) -> np.ndarray:
        rho, sig = theta[:, :1], theta[:, 1:]
        inside = ((rho > 0) & (rho <= 1) & (sig >= 0) & (sig <= 90))[:, 0]
        model = plain_oren_nayar(*geometry, np.clip(rho, 0, 1), np.clip(sig, 0, 90))
        out = -0.5 * np.sum(((model - value) / sigma) ** 2, axis=1)
        return np.where(inside, out, -np.inf)

    began = time.perf_counter()
    start = least_squares(lambda t: (plain_oren_nayar(*geometry, t[0], t[1]) - value) / sigma, [0.8, 20.0],
                          bounds=([0, 0], [1, 90])).x
    rng = np.random.default_rng(seed)
    walkers = start + 1e-4 * np.abs(start) * rng.standard_normal((n_walkers, 2))
    sampler = emcee.EnsembleSampler(n_walkers, 2, log_prob, vectorize=True)
    lsq_seconds = time.perf_counter() - began
    previous, steps = np.inf, 0
    state = emcee.State(walkers, random_state=np.random.RandomState(seed).get_state())
    began = time.perf_counter()
    while steps < 40000:
        state = sampler.run_mcmc(state, 100, progress=False)
        steps += 100
        tau = sampler.get_autocorr_time(tol=0)
        if np.all(tau * 50 < steps) and np.all(np.abs(previous - tau) / tau < 0.05):
            break
        previous = tau
    wall = time.perf_counter() - began
    return _summary("plain emcee baseline", sampler.get_chain(), tau, wall, lsq_seconds, n_walkers)


def _summary(method: str, chain: np.ndarray, tau: np.ndarray, wall: float, lsq_seconds: float,
             n_walkers: int, **extra) -> dict:
    """ESS of sigma (ArviZ bulk, after 2 tau of burn-in) per second, posterior of sigma."""
    burn = int(math.ceil(2 * np.max(tau)))
    kept = chain[burn:, :, 1]
    ess = float(arviz().ess(kept.T, method="bulk"))
    return {"method": method, "n_walkers": n_walkers, "n_steps": int(chain.shape[0]), "tau": [float(t) for t in tau],
            "mcmc_wall_s": wall, "least_squares_wall_s": lsq_seconds, "ess_sigma": ess,
            "ess_sigma_per_s": ess / wall, "median_sigma": float(np.median(kept)), "sd_sigma": float(np.std(kept)),
            "median_rho": float(np.median(chain[burn:, :, 0])), "sd_rho": float(np.std(chain[burn:, :, 0])), **extra}


def gonio_run(data: Dataset, seed: int, n_walkers: int) -> dict:
    """``gonio.fitting.fit`` (least squares + MCMC) with ``n_walkers``."""
    began = time.perf_counter()
    result = fit(data, MODEL, fixed=FIXED, n_walkers=n_walkers, max_steps=40000, seed=seed)
    total = time.perf_counter() - began
    m = result.mcmc
    assert result.free == ("rho", "sigma")
    return _summary(f"gonio, {n_walkers} walkers", m.chain, m.tau, m.wall_seconds, total - m.wall_seconds,
                    n_walkers, converged=bool(m.converged), model_share=m.model_seconds / m.wall_seconds)


def median_record(runs: list[dict]) -> dict:
    """Medians over seeds of the numeric fields (the first run's other fields)."""
    out = dict(runs[0])
    for key, value in runs[0].items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            out[key] = float(np.median([r[key] for r in runs]))
    out["seeds"] = len(runs)
    return out


def agreement(run: dict, reference: dict) -> dict:
    """The posterior of sigma against the reference: |median difference| / sd and sd ratio."""
    return {"median_shift_over_sd": abs(run["median_sigma"] - reference["median_sigma"]) / reference["sd_sigma"],
            "sd_ratio": run["sd_sigma"] / reference["sd_sigma"]}


def time_per_call(function, repeat: int = 3, number: int = 400) -> float:
    """Best-of-``repeat`` seconds per call."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            function()
        best = min(best, (time.perf_counter() - start) / number)
    return float(best)


def evaluation_costs(data: Dataset) -> dict:
    """One log-likelihood through the fit's path against the plain path's prediction."""
    values = {**TRUTH, **FIXED}
    problem = FitProblem(MODEL, data, FIXED)
    vector = np.array([TRUTH[n] for n in problem.free])
    model = gonio.models.get(MODEL)
    walkers = np.tile(vector, (32, 1))
    fast = time_per_call(lambda: problem.log_likelihood(vector))
    batch = time_per_call(lambda: problem.log_likelihood_batch(walkers), number=100) / 32
    plain = time_per_call(lambda: model(*data.geometry, **values))
    baseline = plain_oren_nayar(*data.geometry, 0.9, 30.0)
    return {"likelihood_fixed_geometry_s": fast, "likelihood_per_walker_in_a_batch_of_32_s": batch,
            "prediction_plain_path_s": plain, "n_data": data.n,
            "gonio_vs_baseline_formula_max_relative_difference":
                float(np.max(np.abs(problem.predict(values) / baseline - 1.0)))}


def main() -> int:
    data = benchmark_dataset()
    arviz()  # imported once, before anything is timed
    costs = evaluation_costs(data)
    start = time.perf_counter()
    ls = fit_least_squares(FitProblem(MODEL, data, FIXED))
    ls_seconds = time.perf_counter() - start
    baseline_runs, gonio_runs = [], {w: [] for w in WALKERS}
    for seed in SEEDS:  # interleaved, so that a change of machine load hits every method alike
        baseline_runs.append(plain_emcee_baseline(data, seed))
        print(f"seed {seed}: baseline {baseline_runs[-1]['ess_sigma_per_s']:.0f} ESS/s", flush=True)
        for w in WALKERS:
            gonio_runs[w].append(gonio_run(data, seed, w))
            print(f"seed {seed}: gonio {w} walkers {gonio_runs[w][-1]['ess_sigma_per_s']:.0f} ESS/s "
                  f"({gonio_runs[w][-1]['mcmc_wall_s']:.2f} s)", flush=True)
    baseline = median_record(baseline_runs)
    runs = [median_record(gonio_runs[w]) for w in WALKERS]
    for run in runs:
        run.update(agreement(run, baseline), speedup_ess_per_s=run["ess_sigma_per_s"] / baseline["ess_sigma_per_s"])
    default = next(r for r in runs if r["n_walkers"] == gonio.fitting.mcmc.DEFAULT_WALKERS)
    report = {
        "benchmark": "fitting",
        "command": "python benchmarks/bench_fitting.py",
        "machine": machine(),
        "problem": {"model": MODEL, "truth": TRUTH, "fixed": FIXED, "n_data": data.n, "quantity": data.quantity,
                    "noise": "1 % of each value"},
        "evaluation": costs,
        "least_squares_s": ls_seconds,
        "least_squares_relative_error": max(abs(ls.values[n] / v - 1.0) for n, v in TRUTH.items()),
        "baseline": baseline,
        "gonio": runs,
        "default_walkers": gonio.fitting.mcmc.DEFAULT_WALKERS,
        "default_speedup_ess_per_s": default["speedup_ess_per_s"],
        "targets": {"ess_per_s_at_least_5x_baseline": default["speedup_ess_per_s"] >= 5.0,
                    "median_within_0.5_sd": default["median_shift_over_sd"] <= 0.5,
                    "sd_within_20_percent": abs(default["sd_ratio"] - 1.0) <= 0.2},
        "runs": {"baseline": baseline_runs, "gonio": {str(w): r for w, r in gonio_runs.items()}},
    }
    report["demo_fit"] = emulator_demo_fit()
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "fitting.json").write_text(json.dumps(report, indent=1))
    chart(report, OUT / "fitting.png")
    print(f"baseline: {baseline['ess_sigma_per_s']:.0f} ESS/s of sigma ({baseline['mcmc_wall_s']:.2f} s MCMC)")
    for run in runs:
        print(f"gonio {run['n_walkers']:>3} walkers: {run['ess_sigma_per_s']:>7.0f} ESS/s (x{run['speedup_ess_per_s']:.1f}), "
              f"MCMC {run['mcmc_wall_s']:.2f} s, median shift {run['median_shift_over_sd']:.2f} sd, "
              f"sd ratio {run['sd_ratio']:.2f}, model share {run['model_share']:.0%}")
    print(f"targets: {report['targets']}")
    print(f"wrote {OUT / 'fitting.json'} and {OUT / 'fitting.png'}")
    return 0


def emulator_demo_fit() -> dict:
    """The fit ``gonio demo`` makes, on data measured on the emulated rig (seed 0).

    Relative radiance of the Fig 16 and Fig 19 protocols measured on the exact V-cavity
    model, the model the demo's comparison chose (aperture-averaged), calibration prior on
    the scale, no extra-noise term: MCMC wall time to convergence (50 tau and R-hat < 1.01),
    effective samples per second and the share of time in model evaluation versus the
    sampler.
    """
    import tempfile

    from gonio.cli.demo import TRUTH, fit_demo, measure_demo

    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        reduced = measure_demo(Path(folder), seed=0)
        measure_seconds = time.perf_counter() - start
        start = time.perf_counter()
        result, _ = fit_demo(reduced, seed=0)
        fit_seconds = time.perf_counter() - start
    m = result.mcmc
    ess = result.posterior["ess"]
    share = m.model_seconds / m.wall_seconds
    out = {
        "what": f"gonio demo: {result.model} (aperture-averaged, chosen by the comparison) to emulated Fig 16 + "
                "Fig 19 relative radiance of oren-nayar-exact",
        "r_hat": {k: v["r_hat"] for k, v in m.diagnostics.items()},
        "n_data": int(result.dataset.n),
        "measurement_wall_seconds": measure_seconds,
        "fit_wall_seconds": fit_seconds,
        "mcmc_converged": bool(m.converged),
        "mcmc_steps": m.n_steps,
        "mcmc_walkers": m.n_walkers,
        "tau": dict(zip(result.free, m.tau.tolist())),
        "mcmc_wall_seconds_to_convergence": m.wall_seconds,
        "effective_samples": ess,
        "effective_samples_per_second": {k: v / m.wall_seconds for k, v in ess.items()},
        "model_share": share,
        "sampler_share": 1.0 - share,
        "truth": TRUTH,
        "median": {k: result.posterior["median"][k] for k in TRUTH},
        "p2_5": {k: result.posterior["p2_5"][k] for k in TRUTH},
        "p97_5": {k: result.posterior["p97_5"][k] for k in TRUTH},
    }
    print(f"demo fit: {m.wall_seconds:.1f} s MCMC to convergence ({m.n_steps} steps x {m.n_walkers} walkers), "
          f"ESS/s {min(out['effective_samples_per_second'].values()):.0f}, model share {share:.0%}")
    return out


def chart(report: dict, path: Path) -> None:
    """ESS/s of sigma by ensemble size against the baseline, and MCMC wall time."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 3.8), layout="constrained")
    left, right = fig.subplots(1, 2)
    runs, base = report["gonio"], report["baseline"]
    walkers = [r["n_walkers"] for r in runs]
    left.plot(walkers, [r["ess_sigma_per_s"] for r in runs], "o-", color="C0", label="gonio")
    left.axhline(base["ess_sigma_per_s"], color="C7", ls="--", label="plain emcee baseline (32 walkers)")
    left.axhline(5 * base["ess_sigma_per_s"], color="C3", ls=":", label="target: 5 x baseline")
    left.set(xscale="log", yscale="log", xlabel="walkers", ylabel="effective samples of sigma per second")
    left.set_xticks(walkers, [str(w) for w in walkers])
    left.legend(fontsize=8)
    left.set_title(f"{report['problem']['model']}, {report['problem']['n_data']} points, 2 free parameters", fontsize=10)
    right.plot(walkers, [r["mcmc_wall_s"] for r in runs], "o-", color="C0", label="gonio")
    right.axhline(base["mcmc_wall_s"], color="C7", ls="--", label="baseline")
    right.set(xscale="log", xlabel="walkers", ylabel="MCMC wall time to convergence [s]")
    right.set_xticks(walkers, [str(w) for w in walkers])
    right.set_ylim(bottom=0)
    right.legend(fontsize=8)
    right.set_title(f"default {report['default_walkers']} walkers: x{report['default_speedup_ess_per_s']:.1f} ESS/s",
                    fontsize=10)
    for ax in (left, right):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())

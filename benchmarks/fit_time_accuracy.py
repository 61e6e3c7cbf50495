"""Fit time against accuracy: what each way of stating an interval costs, and how wrong it is.

For three problems, every method gives 95 % intervals of every free parameter; each is
placed by its wall time against the error of its interval endpoints, relative to a very
long reference chain (gonio's sampler, emcee's DE move, 256 walkers x 20000 steps, gonio's likelihood
and priors):

    error = max over parameters and both endpoints |endpoint - reference| / reference sd

(infinite, drawn as an open marker at the top, where a method gives no interval for some
parameter: a least-squares standard error that is undetermined).

Methods:

* **least squares**: the optimum +- 1.96 standard errors of its covariance (the Gauss-Newton
  inverse Hessian); time: the least-squares fit;
* **Laplace**: the same Gaussian, truncated to the parameter's support (its bounds and the
  prior's), endpoints from the truncated normal's quantiles; time: the fit and the
  quantiles;
* **MCMC of a fixed length**: gonio's sampler (default walkers) stopped after 100 to 6400
  steps whatever its diagnostics say, burn-in and thinning as gonio does; time: the fit.

Problems (synthetic, so the posterior is the question, not the model):

* ``gaussian``: Oren-Nayar rho = 0.9, sigma = 30 deg, 201 BRDF values at the Fig 16
  incidences, 1 % noise: a near-Gaussian posterior;
* ``bound``: Lambertian data (rho = 0.5, Fig 16 geometries, 1 % noise) fitted with
  Oren-Nayar: sigma's posterior piles at its bound 0;
* ``skewed``: Minnaert rho = 0.6, k = 0.7 from four views at 15 % noise: k barely
  determined, a skewed posterior.

Writes docs/benchmarks/fit_time_accuracy.json and fit_time_accuracy.png.
Run: ``python benchmarks/fit_time_accuracy.py`` (about two minutes).
"""
from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy import stats

from gonio.fitting import Dataset, FitProblem, fit_least_squares
from gonio.fitting.mcmc import ConvergenceWarning, resolve_priors, sample_posterior
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json  # noqa: E402

#: Chain lengths of the fixed-length MCMC runs [steps].
LENGTHS = (100, 200, 400, 800, 1600, 3200, 6400)
#: Length and ensemble of the reference chain.
REFERENCE_STEPS, REFERENCE_WALKERS = 20000, 256


def _fig16(model: str, truth: dict, noise: float, seed: int) -> Dataset:
    views = np.linspace(-80.0, 80.0, 67)
    geometry = in_plane_angles(np.repeat([30.0, 45.0, 60.0], views.size), np.tile(views, 3))
    exact = predict_quantity(model, "brdf", *geometry, truth)
    rng = np.random.default_rng(seed)
    return Dataset(*geometry, exact * (1 + noise * rng.standard_normal(exact.shape)), noise * exact)


def problems() -> dict[str, FitProblem]:
    """The three problems of the module docstring."""
    gaussian = _fig16("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}, 0.01, 16)
    bound = _fig16("lambert", {"rho": 0.5}, 0.01, 100)
    views = np.array([-60.0, -20.0, 20.0, 60.0])
    geometry = in_plane_angles(np.full(4, 30.0), views)
    exact = predict_quantity("minnaert", "brdf", *geometry, {"rho": 0.6, "k": 0.7})
    skewed = Dataset(*geometry, exact * (1 + 0.15 * np.random.default_rng(4).standard_normal(4)), 0.15 * exact)
    return {"gaussian": FitProblem("oren-nayar", gaussian, {"ir_weight": 1.0}),
            "bound": FitProblem("oren-nayar", bound, {"ir_weight": 1.0}),
            "skewed": FitProblem("minnaert", skewed)}


def _mcmc_intervals(problem: FitProblem, start, steps: int, walkers: int | None = None, seed: int = 1):
    """95 % intervals of a run of exactly ``steps`` steps (no early stop) and its wall time."""
    began = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result, _ = sample_posterior(problem, start, n_walkers=walkers, max_steps=steps, tau_multiple=1e9,
                                     check_every=min(100, steps), seed=seed)
    seconds = time.perf_counter() - began
    samples = result.samples()
    return np.percentile(samples, [2.5, 97.5], axis=0).T, samples.std(axis=0), seconds


def _gaussian_intervals(problem: FitProblem, ls, priors, truncated: bool) -> np.ndarray:
    """Optimum +- 1.96 sd, or the 2.5/97.5 % quantiles of the normal truncated to the support."""
    out = []
    for name in problem.free:
        mu, sd = ls.values[name], ls.stderr[name]
        if not (math.isfinite(sd) and sd > 0):
            out.append([math.nan, math.nan])
            continue
        if not truncated:
            out.append([mu - 1.96 * sd, mu + 1.96 * sd])
            continue
        lo, hi = problem.spec(name).bounds
        lo, hi = max(lo, priors[name].lower), min(hi, priors[name].upper)
        a, b = (lo - mu) / sd, (hi - mu) / sd
        out.append(list(stats.truncnorm.ppf([0.025, 0.975], a, b, loc=mu, scale=sd)))
    return np.array(out)


def _error(intervals: np.ndarray, reference: np.ndarray, sd: np.ndarray) -> float:
    """The largest endpoint error in reference sd; infinite when a parameter has no interval
    (a least-squares standard error that is undetermined, e.g. sigma stationary at 0)."""
    if not np.all(np.isfinite(intervals)):
        return math.inf
    return float(np.max(np.abs(intervals - reference) / sd[:, None]))


def study(name: str, problem: FitProblem) -> dict:
    began = time.perf_counter()
    ls = fit_least_squares(problem)
    ls_seconds = time.perf_counter() - began
    priors = resolve_priors(problem, ls.values)
    reference, reference_sd, reference_seconds = _mcmc_intervals(problem, ls, REFERENCE_STEPS, REFERENCE_WALKERS)
    records = [{"method": "least squares (+-1.96 stderr)", "seconds": ls_seconds,
                "error": _error(_gaussian_intervals(problem, ls, priors, False), reference, reference_sd)}]
    began = time.perf_counter()
    laplace = _gaussian_intervals(problem, ls, priors, True)
    records.append({"method": "Laplace (truncated to the support)", "seconds": ls_seconds + time.perf_counter() - began,
                    "error": _error(laplace, reference, reference_sd)})
    for steps in LENGTHS:
        intervals, _, seconds = _mcmc_intervals(problem, ls, steps)
        records.append({"method": "MCMC", "steps": steps, "seconds": ls_seconds + seconds,
                        "error": _error(intervals, reference, reference_sd)})
    for r in records:
        print(f"{name:9s} {r['method']:38s} {r.get('steps', ''):>5} {r['seconds']:8.3f} s  error {r['error']:.3f} sd",
              flush=True)
    return {"problem": name, "model": problem.model.name, "free": list(problem.free), "n_data": problem.dataset.n,
            "reference": {"steps": REFERENCE_STEPS, "walkers": REFERENCE_WALKERS, "seconds": reference_seconds,
                          "p2_5": reference[:, 0].tolist(), "p97_5": reference[:, 1].tolist(), "sd": reference_sd.tolist()},
            "records": records}


def chart(payload: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    studies = payload["studies"]
    fig = Figure(figsize=(4.0 * len(studies), 3.8), layout="constrained")
    for ax, s in zip(fig.subplots(1, len(studies)), studies):
        mcmc = [r for r in s["records"] if r["method"] == "MCMC"]
        ax.plot([r["seconds"] for r in mcmc], [r["error"] for r in mcmc], "o-", color="C0", label="MCMC, fixed length")
        for r in mcmc:
            ax.annotate(str(r["steps"]), (r["seconds"], r["error"]), textcoords="offset points", xytext=(3, 3), fontsize=7)
        top = max(r["error"] for r in s["records"] if math.isfinite(r["error"])) * 2
        for r, marker, colour in zip(s["records"][:2], ("s", "D"), ("C1", "C2")):
            finite = math.isfinite(r["error"])
            ax.plot([r["seconds"]], [max(r["error"], 1e-3) if finite else top], marker, color=colour,
                    label=r["method"], fillstyle="full" if finite else "none")
            if not finite:
                ax.annotate("no interval for every parameter", (r["seconds"], top), textcoords="offset points",
                            xytext=(4, -10), fontsize=7, color=colour)
        ax.axhline(0.1, color="C7", ls=":", lw=1)
        ax.set(xscale="log", yscale="log", xlabel="wall time [s]", title=f"{s['problem']}: {s['model']} ({', '.join(s['free'])})")
        ax.grid(alpha=0.3)
    fig.axes[0].set_ylabel("error of 95 % endpoints [reference sd]")
    fig.axes[0].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def main() -> int:
    payload = {"benchmark": "fit_time_accuracy", "command": "python benchmarks/fit_time_accuracy.py",
               "machine": machine(), "lengths": list(LENGTHS),
               "studies": [study(name, problem) for name, problem in problems().items()]}
    write_json("fit_time_accuracy", payload)
    chart(payload, OUT / "fit_time_accuracy.png")
    print(f"wrote {OUT / 'fit_time_accuracy.json'} and {OUT / 'fit_time_accuracy.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

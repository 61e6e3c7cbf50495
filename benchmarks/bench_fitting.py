"""Benchmark of the Bayesian fit on a demo-like dataset.

The demo fit is Oren-Nayar (sigma = 30 deg, rho = 0.9, interreflection weight fixed at 1)
to normalised radiance in the plane of incidence at theta_i = 30, 45, 60 deg with the
camera every 5 deg, 1 % noise: the geometries and parameters of Oren & Nayar (1995),
Fig 16.  When ``oren-nayar`` is not registered, Minnaert (rho = 0.6, k = 0.7) on the same
geometries is used instead.

Measured, in one run:

* the cost of one likelihood evaluation through the fixed-geometry fast path
  (``Model.at``, used by the fit) against the plain path (``Model.__call__`` on the same
  geometries, the reference), and the largest relative difference of their predictions;
* least squares: wall time and the relative error of the recovered parameters;
* MCMC (emcee, 32 walkers, run to 50 autocorrelation times): wall time to convergence,
  effective samples per second, and the share of the time spent evaluating the model
  versus in the sampler's own bookkeeping (emcee moves, autocorrelation estimates).

It also times the fit ``gonio demo`` makes on data measured on the emulated rig
(:func:`emulator_demo_fit`).

Writes docs/benchmarks/fitting.json and docs/benchmarks/fitting.png.
Run: ``python benchmarks/bench_fitting.py``.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

import gonio
from gonio.fitting import Dataset, FitProblem, fit, fit_least_squares
from gonio.fitting.problem import combine_prediction, predict_quantity
from gonio.geometry import in_plane_angles

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine  # noqa: E402


def demo_dataset() -> tuple[str, dict, dict, Dataset]:
    """Model name, true free parameters, fixed parameters and the synthetic dataset."""
    if "oren-nayar" in gonio.models.available():
        name, truth, fixed = "oren-nayar", {"rho": 0.9, "sigma": 30.0}, {"ir_weight": 1.0}
    else:
        name, truth, fixed = "minnaert", {"rho": 0.6, "k": 0.7}, {}
    views = np.arange(-80.0, 81.0, 5.0)
    ti = np.repeat([30.0, 45.0, 60.0], views.size)
    geometry = in_plane_angles(ti, np.tile(views, 3))
    exact = predict_quantity(name, "normalised_radiance", *geometry, {**truth, **fixed})
    rng = np.random.default_rng(16)
    data = Dataset(*geometry, exact * (1 + 0.01 * rng.standard_normal(exact.shape)), 0.01 * exact,
                   quantity="normalised_radiance", label=f"synthetic {name}, Oren & Nayar Fig 16 geometries")
    return name, truth, fixed, data


def time_per_call(function, repeat: int = 3, number: int = 400) -> float:
    """Best-of-``repeat`` seconds per call."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            function()
        best = min(best, (time.perf_counter() - start) / number)
    return float(best)


def main() -> int:
    name, truth, fixed, data = demo_dataset()
    values = {**truth, **fixed}
    problem = FitProblem(name, data, fixed)
    vector = np.array([truth[n] for n in problem.free])
    model = gonio.models.get(name)
    ti, pi_, tr, pr = data.geometry
    sources, index = data.incidences()

    def reference_prediction() -> np.ndarray:
        brdf = model(ti, pi_, tr, pr, **values)
        normal = model(sources[:, 0], sources[:, 1], 0.0, sources[:, 1], **values)[index]
        return combine_prediction("normalised_radiance", brdf, normal, np.cos(np.radians(ti)), 1.0)

    fast_seconds = time_per_call(lambda: problem.log_likelihood(vector))
    reference_seconds = time_per_call(lambda: reference_prediction())
    path_error = float(np.max(np.abs(problem.predict(values) / reference_prediction() - 1.0)))

    start = time.perf_counter()
    ls = fit_least_squares(problem)
    ls_seconds = time.perf_counter() - start
    ls_error = max(abs(ls.values[n] / v - 1.0) for n, v in truth.items())

    start = time.perf_counter()
    result = fit(data, name, fixed=fixed, n_walkers=32, max_steps=40000, tau_multiple=50.0, seed=1)
    total = time.perf_counter() - start
    m = result.mcmc
    ess = result.posterior["ess"]
    mcmc_error = max(abs(result.posterior["median"][n] / v - 1.0) for n, v in truth.items())
    model_share = m.model_seconds / m.wall_seconds
    records = [
        {"family": name, "method": "likelihood, fixed-geometry path (Model.at)", "seconds_per_evaluation": fast_seconds,
         "relative_error": path_error, "reference_method": "Model.__call__ on the same geometries",
         "notes": f"{data.n} measurements; relative error = largest difference of the two paths' predictions"},
        {"family": name, "method": "prediction, plain path (Model.__call__)", "seconds_per_evaluation": reference_seconds,
         "relative_error": 0.0, "reference_method": "itself", "notes": "reference"},
        {"family": name, "method": "least squares (trf, 6 starts)", "seconds_per_evaluation": ls_seconds,
         "relative_error": ls_error, "reference_method": "true parameters",
         "notes": "seconds for the whole fit; error = largest relative deviation from the truth"},
        {"family": name, "method": "emcee to 50 tau (32 walkers)", "seconds_per_evaluation": m.wall_seconds / max(m.evaluations, 1),
         "relative_error": mcmc_error, "reference_method": "true parameters",
         "notes": f"{m.evaluations} likelihood evaluations in {m.wall_seconds:.2f} s; error of the posterior median"},
    ]
    report = {
        "benchmark": "fitting",
        "command": "python benchmarks/bench_fitting.py",
        "machine": machine(),
        "records": records,
        "demo": {"model": name, "truth": truth, "fixed": fixed, "n_data": data.n, "quantity": data.quantity},
        "fast_path_speedup": reference_seconds / fast_seconds,
        "mcmc": {
            "converged": bool(m.converged),
            "n_walkers": m.n_walkers,
            "n_steps": m.n_steps,
            "tau": dict(zip(result.free, m.tau.tolist())),
            "wall_seconds_to_convergence": m.wall_seconds,
            "total_fit_seconds": total,
            "effective_samples": ess,
            "effective_samples_per_second": {k: v / m.wall_seconds for k, v in ess.items()},
            "model_seconds": m.model_seconds,
            "sampler_seconds": m.wall_seconds - m.model_seconds,
            "model_share": model_share,
            "sampler_share": 1.0 - model_share,
            "acceptance_fraction": result.posterior["acceptance_fraction"],
            "median": result.posterior["median"],
            "p2_5": result.posterior["p2_5"],
            "p97_5": result.posterior["p97_5"],
        },
    }
    report["demo_fit"] = emulator_demo_fit()
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "fitting.json").write_text(json.dumps(report, indent=1))
    chart(report, OUT / "fitting.png")
    print(json.dumps(report["mcmc"], indent=1))
    print(f"fast path {fast_seconds * 1e6:.1f} us vs plain path {reference_seconds * 1e6:.1f} us per evaluation "
          f"(x{reference_seconds / fast_seconds:.2f}); paths agree to {path_error:.1e}")
    print(f"least squares {ls_seconds:.3f} s, max relative error {ls_error:.2e}")
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
    """Two panels: cost per evaluation of both paths, and where the MCMC time goes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 3.8), layout="constrained")
    left, right = fig.subplots(1, 2)
    records = report["records"][:2]
    labels = ["fixed-geometry\n(Model.at)", "plain\n(Model.__call__)"]
    times = [r["seconds_per_evaluation"] * 1e6 for r in records]
    left.barh(labels, times, color=["C0", "C7"])
    for y, t in enumerate(times):
        left.text(t, y, f" {t:.0f} us", va="center")
    left.set_xlabel("time per likelihood / prediction [us]")
    left.set_title(f"Model evaluation, {report['demo']['model']}, {report['demo']['n_data']} points "
                   f"(x{report['fast_path_speedup']:.2f})", fontsize=10)
    left.set_xlim(0, max(times) * 1.3)
    m = report["mcmc"]
    right.barh(["MCMC"], [m["model_seconds"]], color="C0", label="model evaluation")
    right.barh(["MCMC"], [m["sampler_seconds"]], left=[m["model_seconds"]], color="C1", label="sampler (emcee, tau)")
    right.set_xlabel("wall time to convergence [s]")
    ess = min(m["effective_samples_per_second"].values())
    right.set_title(f"emcee to 50 tau: {m['n_steps']} steps x {m['n_walkers']} walkers\n"
                    f"model evaluation {100 * m['model_share']:.0f} % of the time; {ess:.0f} effective samples/s",
                    fontsize=10)
    right.legend(loc="lower right", fontsize=8)
    for ax in (left, right):
        ax.grid(axis="x", alpha=0.3)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())

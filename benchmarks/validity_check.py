"""Does the fitter's validity check predict what an approximation does to a fit?

``gonio.fitting.fit`` compares an approximate model with its exact reference at the fit's
own data and optimum (gonio/fitting/validity.py) and predicts, by linearisation, how far
the formula's error moves each parameter. This script measures that prediction against
the shift it predicts: the same data (the exact V-cavity model, ``oren-nayar-exact``, with
Gaussian relative noise) fitted by least squares with the approximation and with the exact
model; the shift is the approximation's optimum minus the exact model's. Cases: the
functional model (``oren-nayar``, ``ir_weight = 1``) and the qualitative one (eq 36) at
sigma 5, 10, 20, 30, 40 deg, rho 0.9, in-plane sweeps of theta_r from -80 to 80 deg in
5-deg steps at theta_i 15, 45 and 75 deg (at normal incidence the in-plane
sweep of the functional model leaves rho and sigma degenerate, nothing to check), noise 0.3 % (the middle of a national
laboratory's range, 0.15-0.6 % at k = 2), and whether the fit is flagged (a parameter moved
by more than 0.5 standard errors or a value 3 uncertainties off); then, at sigma 30 deg and
theta_i 45 deg, relative noise from 0.1 % to 30 %: where the flag stops.

Writes docs/benchmarks/validity_check.json and validity_check.png. Run:
``python benchmarks/validity_check.py`` (about 2.5 minutes).
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from _common import OUT, machine, write_json

import gonio
from gonio.fitting import Dataset, fit

SIGMAS = (5.0, 10.0, 20.0, 30.0, 40.0)
INCIDENCES = (15.0, 45.0, 75.0)
MODELS = {"oren-nayar": {"ir_weight": 1.0}, "oren-nayar-qualitative": {}}
NOISE = 0.003
#: Relative noise levels of the sweep at sigma 30 deg, theta_i 45 deg [-].
NOISE_SWEEP = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3)
VIEWS = np.arange(-80.0, 81.0, 5.0)


def case(model: str, sigma_deg: float, theta_i: float, seed: int, noise: float = NOISE) -> dict:
    """One comparison: predicted and measured shifts of rho and sigma."""
    theta_r, phi_r = np.abs(VIEWS), np.where(VIEWS < 0, 180.0, 0.0)
    truth = gonio.brdf("oren-nayar-exact", theta_i, 0.0, theta_r, phi_r, rho=0.9, sigma=sigma_deg)
    value = truth * (1 + noise * np.random.default_rng(seed).standard_normal(truth.size))
    data = Dataset(theta_i, 0.0, theta_r, phi_r, value, noise * truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        approximate = fit(data, model, fixed=MODELS[model], mcmc=False, seed=seed)
        exact = fit(data, "oren-nayar-exact", mcmc=False, seed=seed)
    check = approximate.validity
    row = {"model": model, "sigma": sigma_deg, "theta_i": theta_i, "seed": seed, "noise": noise,
           "flagged": check.exceeded,
           "worst_point_sd": check.worst_point(),
           "max_relative_error": float(np.max(np.abs(check.relative_error)))}
    for name in ("rho", "sigma"):
        row[f"{name}_measured_shift"] = approximate.best_values()[name] - exact.best_values()[name]
        row[f"{name}_predicted_shift"] = check.bias[name]
        row[f"{name}_predicted_sd"] = check.bias_sd[name]
        row[f"{name}_stderr"] = approximate.least_squares.stderr[name]
    return row


def summary(rows: list[dict]) -> dict:
    """How often the prediction agrees with the measured shift, per parameter: the same side
    of the 0.5-sd limit, the same sign, within a factor 2."""
    out = {}
    for name in ("rho", "sigma"):
        measured = np.array([r[f"{name}_measured_shift"] / r[f"{name}_stderr"] for r in rows])
        predicted = np.array([r[f"{name}_predicted_shift"] / r[f"{name}_stderr"] for r in rows])
        ratio = predicted / measured
        out[name] = {
            "cases": len(rows),
            "same_side_of_limit": int(np.sum((np.abs(measured) > 0.5) == (np.abs(predicted) > 0.5))),
            "same_sign": int(np.sum(np.sign(measured) == np.sign(predicted))),
            "within_factor_2": int(np.sum((ratio >= 0.5) & (ratio <= 2.0))),
            "measured_beyond_limit": int(np.sum(np.abs(measured) > 0.5)),
        }
    return out


def chart(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    for ax, name, unit in zip(axes, ("sigma", "rho"), ("deg", "-")):
        for model, marker in zip(MODELS, ("o", "s")):
            chosen = [r for r in rows if r["model"] == model]
            measured = np.array([r[f"{name}_measured_shift"] / r[f"{name}_stderr"] for r in chosen])
            predicted = np.array([r[f"{name}_predicted_shift"] / r[f"{name}_stderr"] for r in chosen])
            ax.scatter(measured, predicted, marker=marker, s=24, label=model, alpha=0.8)
        limit = max(abs(v) for ax_ in [ax] for v in ax.get_xlim() + ax.get_ylim())
        ax.plot([-limit, limit], [-limit, limit], "k-", lw=0.8, label="predicted = measured")
        ax.axvspan(-0.5, 0.5, color="tab:green", alpha=0.12, label="within the 0.5 sd limit")
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_xlabel(f"measured shift of {name} [standard errors] (approximation - exact fit)")
        ax.set_ylabel("shift predicted by the check [standard errors]")
        ax.set_title(f"{name} [{unit}]", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Exact V-cavity data, {NOISE:.1%} noise: the check's predicted bias against the real one", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    start = time.perf_counter()
    rows = [case(model, sigma_deg, theta_i, seed=k)
            for model in MODELS for sigma_deg in SIGMAS for k, theta_i in enumerate(INCIDENCES)]
    sweep = [case(model, 30.0, 45.0, seed=k, noise=noise)
             for model in MODELS for k, noise in enumerate(NOISE_SWEEP)]
    for row in rows + sweep:
        print(f"noise {row['noise']:.2%} ", end="")
        print(f"{row['model']:<24} sigma {row['sigma']:>4g} theta_i {row['theta_i']:>4g}: sigma shift "
              f"{row['sigma_measured_shift']:+.3f} measured, {row['sigma_predicted_shift']:+.3f} predicted; "
              f"flagged {row['flagged']}", flush=True)
    payload = {
        "description": __doc__.split("\n\n")[0],
        "command": "python benchmarks/validity_check.py",
        "machine": machine(),
        "noise": NOISE,
        "rows": rows,
        "noise_sweep": sweep,
        "summary": summary(rows),
        "seconds": time.perf_counter() - start,
    }
    print(payload["summary"])
    print(write_json("validity_check", payload))
    chart(rows, OUT / "validity_check.png")


if __name__ == "__main__":
    main()

"""Where fits and the sampler fail: bias and 95 % coverage of least squares, Laplace and MCMC,
and the sampler's steps and failures, over axes varied one at a time around a base case.

Truth and fit differ as they do for a user: the data are the exact V-cavity model
(``oren-nayar-exact``, rho = 0.8, its interreflection included; its two components f1, f2
are evaluated once per geometry and sigma and cached, in memory and in
``benchmarks/_build/validity_fits_exact.pkl``) with Gaussian relative noise (value =
truth x (1 + e N(0, 1)), stated uncertainty e x truth), and the fit is ``gonio.fitting.fit``
with ``oren-nayar-tabulated`` and its defaults (a table polished by the exact model where the
table's error at the data's geometries exceeds a tenth of their uncertainties, uniform
priors over the physical ranges, log-uniform over six decades for a free ``scale``).

Base case: incidences theta_i = 30 and 60 deg, N = 32 values (half at each), views in the
plane of incidence evenly spaced over theta_r in [-70, 70] deg (signed), sigma = 20 deg,
relative noise 1 %, absolute BRDF (``scale`` fixed: a calibrated rig). Axes, each varied
alone (``AXES``):

* ``noise``: relative noise per value 0.1 % to 10 %;
* ``points``: N = 8 to 128;
* ``sigma``: true sigma 0 to 40 deg (0: Lambertian, sigma on its bound, not identifiable);
* ``coverage``: largest |theta_r| 30 to 85 deg, in the plane of incidence or with the views'
  azimuths cycling over 0, 45, 90, 135, 180 deg from the source's (out of plane);
* ``scale``: relative radiance (prediction ``scale f cos theta_i``) with ``scale`` free and
  no reference standard (default prior), or with a standard known to 1 % (normal prior on
  scale), against the base (scale fixed, absolute BRDF).

Per fit and free parameter (sigma, rho, and scale where free), three 95 % intervals:

* **least squares**: optimum +- 1.96 standard errors of gonio's covariance (J^T J)^-1
  (``FitResult.least_squares``; no interval where the standard error is undetermined);
* **Laplace**: gonio's least-squares Gaussian (the posterior mode and the Laplace
  covariance, docs/fitting.md) truncated to the parameter's support (bounds and prior),
  its 2.5/97.5 % quantiles and median, as in benchmarks/fit_time_accuracy.py (gonio has no
  separate Laplace interval; its Laplace approximation serves the evidence);
* **MCMC**: the posterior's 2.5/97.5 % percentiles and median (``FitResult.posterior``).

Bias is (point - truth) in units of the MCMC posterior sd, averaged over seeds (the
point: the optimum, the truncated Gaussian's median, the posterior median); coverage the
fraction of seeds whose interval holds the truth, with Wilson 95 % intervals. Sampler map
per fit: steps run, ``FitResult.converged`` (not converged within the cap = failure), the
largest R-hat and tau, and the MCMC warnings gonio attaches (acceptance outside [0.1, 0.9],
stuck walkers, posterior piled at a bound, strongly correlated pairs). ``rules`` in the JSON
are statements a fitter can check, derived from these numbers by :func:`rules`.

The seeds' noise draws are common to the cells (seed s draws the same standard normals in
every cell with the same N), so the cells of an axis differ by its setting rather than by
their draws, and their coverages are not independent estimates. Twenty seeds put a Wilson
interval of [0.76, 0.99] around 19 of 20; a cell whose coverage of some parameter lies
wholly below 0.95 by that interval is re-measured by ``CONFIRM_FITS`` least-squares fits of
an independent noise stream (``confirmation`` in the cell; kept in
``validity_fits_confirm.jsonl``). ``noise_free_shift_stderr`` is, per cell, the fitted
table's own bias: its least-squares fit to the exact model's noise-free values.

Every fit is one JSON line appended to ``docs/benchmarks/validity_fits.jsonl`` (git-ignored)
as it finishes; a run skips the (cell, seed) pairs already there, so a stopped run resumes.

Run: ``python benchmarks/validity_fits.py`` (all axes, 20 seeds, MCMC capped at 10000
steps instead of gonio's 20000 to bound the run time; about 25 minutes in one process, a
quarter of it the 20 chains of the scale-free cell that reach the cap); ``--axis NAME`` for
one axis (the JSON and figures are always made from every record present); ``--quick`` for a
smoke run (3 seeds, the ends of each axis, 2000 steps; writes ``*_quick``); ``--max-steps
20000 --axis scale --seeds 10`` re-runs the scale axis at gonio's own cap (writes
``validity_fits_cap20000.*``); ``--summary-only`` remakes the JSON and figures. Writes
``docs/benchmarks/validity_fits.json``, ``validity_fits.png`` (bias and coverage) and
``validity_fits_sampler.png`` (steps and failures).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, mcmc_design, wilson, write_json  # noqa: E402

TRUTH_MODEL = "oren-nayar-exact"
FIT_MODEL = "oren-nayar-tabulated"
RHO = 0.8
INCIDENCES = (30.0, 60.0)
#: Azimuths of the views out of the plane of incidence, relative to the source's [deg].
AZIMUTHS = (0.0, 45.0, 90.0, 135.0, 180.0)
#: Relative sd of the scale's prior with a reference standard.
STANDARD = 0.01
BASE = {"noise": 0.01, "points": 32, "sigma": 20.0, "theta_r_max": 70.0, "azimuths": "in-plane", "scale": "fixed"}
AXES: dict[str, list[dict[str, Any]]] = {
    "noise": [{"noise": e} for e in (0.001, 0.003, 0.01, 0.03, 0.1)],
    "points": [{"points": n} for n in (8, 16, 32, 64, 128)],
    "sigma": [{"sigma": s} for s in (0.0, 2.0, 5.0, 10.0, 20.0, 30.0, 40.0)],
    "coverage": [{"theta_r_max": t, "azimuths": a} for a in ("in-plane", "out-of-plane") for t in (30.0, 50.0, 70.0, 85.0)],
    "scale": [{"scale": s} for s in ("fixed", "standard", "free")],
}
#: Seeds' noise draws: default_rng((NOISE_STREAM, seed)), the same for every cell.
NOISE_STREAM = 20261206
RECORDS = OUT / "validity_fits.jsonl"
CACHE = ROOT / "benchmarks" / "_build" / "validity_fits_exact.pkl"
METHODS = ("least squares", "Laplace", "MCMC")
#: The MCMC step cap of the study (gonio's default is 20000; see the module docstring).
DEFAULT_CAP = 10000

_exact_cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_cache_dirty = False


def cell_key(settings: dict[str, Any]) -> str:
    return "|".join(f"{name}={settings[name]}" for name in BASE)


def geometry(settings: dict[str, Any]) -> tuple[np.ndarray, ...]:
    """(theta_i, phi_i, theta_r, phi_r) [deg] of a cell: half the points at each incidence,
    |theta_r| as the signed in-plane views evenly spaced over [-max, max]."""
    n = int(settings["points"]) // len(INCIDENCES)
    views = np.linspace(-settings["theta_r_max"], settings["theta_r_max"], n)
    ti, pi_, tr, pr = [], [], [], []
    for k, theta_i in enumerate(INCIDENCES):
        ti.append(np.full(n, theta_i))
        pi_.append(np.zeros(n))
        tr.append(np.abs(views))
        if settings["azimuths"] == "in-plane":
            pr.append(np.where(views >= 0.0, 0.0, 180.0))
        else:
            pr.append(np.array([AZIMUTHS[(j + k) % len(AZIMUTHS)] for j in range(n)]))
    return tuple(np.concatenate(a) for a in (ti, pi_, tr, pr))


def _load_cache() -> None:
    if not _exact_cache and CACHE.exists():
        try:
            _exact_cache.update(pickle.loads(CACHE.read_bytes()))
        except Exception:  # noqa: BLE001 - a damaged cache is recomputed
            pass


def save_cache() -> None:
    global _cache_dirty
    if _cache_dirty:
        CACHE.parent.mkdir(parents=True, exist_ok=True)
        CACHE.write_bytes(pickle.dumps(_exact_cache))
        _cache_dirty = False


def exact_brdf(angles: tuple[np.ndarray, ...], sigma: float, rho: float = RHO) -> np.ndarray:
    """``oren-nayar-exact`` at ``angles``: rho f1 + rho^2 f2, f1 and f2 cached per geometry."""
    global _cache_dirty
    from gonio.models.oren_nayar.exact import exact_components

    _load_cache()
    key = (float(sigma), tuple(np.round(np.concatenate(angles), 9)))
    if key not in _exact_cache:
        _exact_cache[key] = tuple(np.asarray(c, float) for c in exact_components(*angles, float(sigma)))
        _cache_dirty = True
    f1, f2 = _exact_cache[key]
    return rho * f1 + rho**2 * f2


def dataset(settings: dict[str, Any], seed: int):
    """The cell's noisy data for ``seed`` and the true values of the free parameters."""
    from gonio.fitting import Dataset

    angles = geometry(settings)
    truth = exact_brdf(angles, settings["sigma"])
    quantity, values = "brdf", {"rho": RHO, "sigma": float(settings["sigma"])}
    if settings["scale"] != "fixed":  # relative radiance, true scale 1
        truth = truth * np.cos(np.radians(angles[0]))
        quantity, values["scale"] = "radiance", 1.0
    rng = np.random.default_rng((NOISE_STREAM, seed))
    noise = settings["noise"]
    data = Dataset(*angles, truth * (1.0 + noise * rng.standard_normal(truth.shape)), noise * truth, quantity=quantity)
    return data, values


def _interval(point: float, lo: float, hi: float, sd: float, truth: float, mcmc_sd: float) -> dict[str, Any]:
    ok = all(math.isfinite(x) for x in (point, lo, hi))
    return {"point": point if ok else None, "lo": lo if ok else None, "hi": hi if ok else None,
            "sd": sd if ok and math.isfinite(sd) else None,
            "covered": (lo <= truth <= hi) if ok else None,
            "below_upper": (truth <= hi) if ok else None,
            "z": (point - truth) / mcmc_sd if ok and mcmc_sd > 0 else None}


def gaussian_intervals(result, truth: dict[str, float], mcmc_sd: dict[str, float]) -> dict[str, dict]:
    """Least-squares and Laplace (truncated to the support) intervals of every free parameter."""
    from scipy import stats

    problem = result.problem()
    ls = result.least_squares
    out: dict[str, dict] = {"least squares": {}, "Laplace": {}}
    for name in result.free:
        mu, sd = float(ls.values[name]), float(ls.stderr.get(name, math.nan))
        if not (math.isfinite(sd) and sd > 0):
            for method in out:
                out[method][name] = _interval(math.nan, math.nan, math.nan, math.nan, truth[name], mcmc_sd[name])
            continue
        out["least squares"][name] = _interval(mu, mu - 1.96 * sd, mu + 1.96 * sd, sd, truth[name], mcmc_sd[name])
        lo, hi = problem.spec(name).bounds
        prior = result.priors.get(name)
        if prior is not None:
            lo, hi = max(lo, getattr(prior, "lower", lo)), min(hi, getattr(prior, "upper", hi))
        a, b = (lo - mu) / sd, (hi - mu) / sd
        q_lo, median, q_hi = stats.truncnorm.ppf([0.025, 0.5, 0.975], a, b, loc=mu, scale=sd)
        out["Laplace"][name] = _interval(float(median), float(q_lo), float(q_hi), float(stats.truncnorm.std(a, b, scale=sd)),
                                         truth[name], mcmc_sd[name])
    return out


def _tags(flags: list[str]) -> list[str]:
    """Short names of the warnings a fit carries (the full text stays in ``flags``)."""
    tags = []
    for f in flags:
        low = f.lower()
        if low.startswith("noise understated") or low.startswith("model inadequate"):
            tags.append("goodness of fit: " + low.split(":")[0].replace("model ", ""))
        elif low.startswith("chain not converged"):
            tags.append("not converged")
        elif "acceptance fraction" in low:
            tags.append("acceptance outside [0.1, 0.9]")
        elif "stuck walkers" in low:
            tags.append("stuck walkers")
        elif "piles up at the lower bound" in low:
            tags.append(f"{f.split(':')[0]} piled at lower bound")
        elif "piles up at the upper bound" in low:
            tags.append(f"{f.split(':')[0]} piled at upper bound")
        elif "strongly correlated in the posterior" in low:
            tags.append("strongly correlated: " + " and ".join(f.split(" are strongly")[0].split(" and ")))
        elif low.startswith("polished with"):
            tags.append("polished by the exact model")
        elif "lies at the lower bound" in low or "lies at the upper bound" in low:
            tags.append(f"least squares: {f.split()[0]} at a bound")
        elif "not constrained" in low:
            tags.append(f"least squares: {f.split()[0]} not constrained")
        elif "insensitive" in low:
            tags.append(f"least squares: {f.split()[0]} insensitive")
        elif "degenerate" in low:
            tags.append("least squares: degenerate")
        else:
            tags.append("least squares / other: " + f[:60])
    return tags


def run_fit(settings: dict[str, Any], seed: int, max_steps: int = 10000) -> dict[str, Any]:
    """One cell and seed: the data, gonio's fit (least squares, Laplace, MCMC), and the record
    of every interval and of the sampler."""
    from gonio.fitting import fit
    from gonio.fitting.mcmc import ConvergenceWarning
    from gonio.fitting.priors import Normal

    data, truth = dataset(settings, seed)
    priors = {"scale": Normal(1.0, STANDARD, 0.0, math.inf)} if settings["scale"] == "standard" else None
    began = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result = fit(data, FIT_MODEL, priors=priors, seed=seed, max_steps=max_steps)
    seconds = time.perf_counter() - began
    samples = result.samples()
    mcmc_sd = {name: float(np.std(samples[:, k], ddof=1)) for k, name in enumerate(result.free)}
    intervals = gaussian_intervals(result, truth, mcmc_sd)
    post = result.posterior
    intervals["MCMC"] = {name: _interval(float(post["median"][name]), float(post["p2_5"][name]),
                                         float(post["p97_5"][name]), mcmc_sd[name], truth[name], mcmc_sd[name])
                         for name in result.free}
    correlation = np.asarray(post["correlation"], float)
    free = list(result.free)
    pairs = {f"{free[i]}-{free[j]}": float(correlation[i, j]) for i in range(len(free)) for j in range(i + 1, len(free))}
    mcmc = result.mcmc
    diagnostics = mcmc.diagnostics
    return {
        "cell": cell_key(settings), "settings": settings, "seed": seed, "max_steps": max_steps, "truth": truth,
        "free": free, "intervals": intervals, "posterior_correlation": pairs,
        "ls_correlation": {f"{free[i]}-{free[j]}": float(result.least_squares.correlation[i, j])
                           for i in range(len(free)) for j in range(i + 1, len(free))},
        "sampler": {"steps": mcmc.n_steps, "converged": bool(result.converged),
                    "acceptance": float(np.mean(mcmc.acceptance_fraction)),
                    "tau_max": float(np.nanmax(mcmc.tau)) if np.any(np.isfinite(mcmc.tau)) else None,
                    "rhat_max": float(max(d["r_hat"] for d in diagnostics.values())),
                    "ess_bulk_min": float(min(d.get("ess_bulk", math.nan) for d in diagnostics.values())),
                    "seconds": mcmc.wall_seconds},
        "ls_warnings": list(result.least_squares.warnings),
        "tags": _tags(result.flags), "flags": result.flags,
        "verdict": result.adequacy.verdict if result.adequacy is not None else None,
        "seconds": seconds,
    }


def noise_free(settings: dict[str, Any]) -> dict[str, float]:
    """The least-squares fit of the cell's model to its noise-free data (the exact model's
    values, the cell's stated uncertainties): how far the fitted model's own error moves each
    parameter, in its standard errors (the part of a bias no seed averages away)."""
    from gonio.fitting import fit
    from gonio.fitting.priors import Normal

    data, truth = dataset(settings, 0)
    exact = exact_brdf(geometry(settings), settings["sigma"])
    if data.quantity == "radiance":
        exact = exact * np.cos(np.radians(data.theta_i))
    clean = type(data)(data.theta_i, data.phi_i, data.theta_r, data.phi_r, exact, data.sigma, quantity=data.quantity)
    priors = {"scale": Normal(1.0, STANDARD, 0.0, math.inf)} if settings["scale"] == "standard" else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = fit(clean, FIT_MODEL, priors=priors, mcmc=False)
    ls = result.least_squares
    return {name: ((ls.values[name] - truth[name]) / ls.stderr[name]
                   if math.isfinite(ls.stderr.get(name, math.nan)) and ls.stderr[name] > 0 else None)
            for name in result.free}


#: Least-squares fits (an independent noise stream) that re-measure a cell whose coverage
#: looked below nominal with the cell's seeds.
CONFIRM_FITS = 200
CONFIRM_STREAM = 99


def confirm(settings: dict[str, Any], fits: int = CONFIRM_FITS) -> dict[str, Any]:
    """Least-squares coverage of the cell over ``fits`` further seeds of another noise stream
    (no MCMC: where MCMC and least squares agreed in the cell, this re-measures both)."""
    global NOISE_STREAM
    from gonio.fitting import fit
    from gonio.fitting.priors import Normal

    priors = {"scale": Normal(1.0, STANDARD, 0.0, math.inf)} if settings["scale"] == "standard" else None
    kept, NOISE_STREAM = NOISE_STREAM, CONFIRM_STREAM
    z: dict[str, list[float]] = {}
    try:
        for seed in range(fits):
            data, truth = dataset(settings, seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ls = fit(data, FIT_MODEL, priors=priors, mcmc=False).least_squares
            for name in ls.free:
                sd = ls.stderr.get(name, math.nan)
                z.setdefault(name, []).append((ls.values[name] - truth[name]) / sd if sd > 0 else math.nan)
    finally:
        NOISE_STREAM = kept
    out = {"fits": fits, "noise_stream": CONFIRM_STREAM, "params": {}}
    for name, values in z.items():
        v = np.array(values, float)
        given = v[np.isfinite(v)]
        k = int(np.sum(np.abs(given) <= 1.96))
        out["params"][name] = {"with_interval": int(given.size), "covered": k,
                               "coverage": k / given.size if given.size else None, "wilson": wilson(k, int(given.size)),
                               "rms_z": float(np.sqrt(np.mean(given**2))) if given.size else None,
                               "mean_z": float(np.mean(given)) if given.size else None}
    return out


def needs_confirmation(summary: dict[str, Any]) -> bool:
    """Whether some interval's coverage in the cell lies wholly below 0.95 (Wilson)."""
    for name, row in summary["params"].items():
        if name == "sigma" and summary["settings"]["sigma"] == 0.0:
            continue  # a central interval cannot hold a truth on the bound (rules: "sigma near 0")
        if any(row[m]["coverage"] is not None and row[m]["wilson"][1] < 0.95 for m in METHODS):
            return True
    return False


# ------------------------------------------------------------------------------- summary
def _mean_se(values: list[float]) -> tuple[float | None, float | None]:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], float)
    if v.size == 0:
        return None, None
    return float(v.mean()), (float(v.std(ddof=1) / math.sqrt(v.size)) if v.size > 1 else None)


def summarise_cell(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Coverage, bias and sampler figures of one cell's fits."""
    n = len(records)
    params: dict[str, Any] = {}
    for name in records[0]["free"]:
        truth = records[0]["truth"][name]
        row: dict[str, Any] = {"truth": truth}
        mcmc_widths = [r["intervals"]["MCMC"][name]["hi"] - r["intervals"]["MCMC"][name]["lo"] for r in records]
        for method in METHODS:
            items = [r["intervals"][method][name] for r in records]
            given = [i for i in items if i["covered"] is not None]
            k = sum(bool(i["covered"]) for i in given)
            upper = sum(bool(i["below_upper"]) for i in given)
            z_mean, z_se = _mean_se([i["z"] for i in given])
            err_mean, err_se = _mean_se([i["point"] - truth for i in given])
            ratios = [(i["hi"] - i["lo"]) / w for i, w in zip(items, mcmc_widths) if i["covered"] is not None and w > 0]
            row[method] = {
                "n": n, "with_interval": len(given), "covered": k,
                "coverage": k / len(given) if given else None, "wilson": wilson(k, len(given)),
                "upper_limit_coverage": upper / len(given) if given else None,
                "bias_sd": z_mean, "bias_sd_se": z_se, "bias": err_mean, "bias_se": err_se,
                "rms_z": float(np.sqrt(np.mean(np.square([i["z"] for i in given if i["z"] is not None]))))
                if given else None,
                "width_median": float(np.median([i["hi"] - i["lo"] for i in given])) if given else None,
                "width_over_mcmc_median": float(np.median(ratios)) if ratios else None,
            }
        row["piled_at_lower_bound"] = sum(f"{name} piled at lower bound" in _tags(r["flags"]) for r in records) / n
        row["piled_at_upper_bound"] = sum(f"{name} piled at upper bound" in _tags(r["flags"]) for r in records) / n
        row["ls_undetermined"] = sum(r["intervals"]["least squares"][name]["covered"] is None for r in records) / n
        params[name] = row
    steps = np.array([r["sampler"]["steps"] for r in records], float)
    failed = sum(not r["sampler"]["converged"] for r in records)
    tags: dict[str, int] = {}
    for r in records:
        for t in set(_tags(r["flags"])):
            tags[t] = tags.get(t, 0) + 1
    correlations = {}
    for pair in records[0]["posterior_correlation"]:
        values = np.array([r["posterior_correlation"][pair] for r in records], float)
        correlations[pair] = {"median": float(np.nanmedian(values)),
                              "median_abs": float(np.nanmedian(np.abs(values))),
                              "above_0.95": int(np.sum(np.abs(values) > 0.95))}
    return {
        "cell": records[0]["cell"], "settings": records[0]["settings"], "seeds": n, "free": records[0]["free"],
        "params": params, "posterior_correlation": correlations,
        "sampler": {"steps_median": float(np.median(steps)), "steps_p10": float(np.percentile(steps, 10)),
                    "steps_p90": float(np.percentile(steps, 90)), "steps_max": int(steps.max()),
                    "failed": failed, "failure_rate": failed / n, "failure_wilson": wilson(failed, n),
                    "rhat_max_median": float(np.median([r["sampler"]["rhat_max"] for r in records])),
                    "tau_max_median": float(np.nanmedian([np.nan if r["sampler"]["tau_max"] is None
                                                          else r["sampler"]["tau_max"] for r in records])),
                    "acceptance_median": float(np.median([r["sampler"]["acceptance"] for r in records])),
                    "max_steps": records[0]["max_steps"]},
        "warnings": dict(sorted(tags.items())),
        "verdicts": {v: sum(r["verdict"] == v for r in records) for v in sorted({str(r["verdict"]) for r in records})},
        "fit_seconds_median": float(np.median([r["seconds"] for r in records])),
        "fit_seconds_total": float(np.sum([r["seconds"] for r in records])),
    }


def axis_cells(name: str) -> list[dict[str, Any]]:
    return [{**BASE, **change} for change in AXES[name]]


def axis_label(axis: str, settings: dict[str, Any]) -> str:
    if axis == "noise":
        return f"{100 * settings['noise']:g} %"
    if axis == "points":
        return f"{settings['points']}"
    if axis == "sigma":
        return f"{settings['sigma']:g}"
    if axis == "coverage":
        return f"{settings['theta_r_max']:g} {'in' if settings['azimuths'] == 'in-plane' else 'out'}"
    return {"fixed": "fixed (BRDF)", "standard": "free, 1 % standard", "free": "free, no standard"}[settings["scale"]]


AXIS_TITLES = {"noise": "relative noise per value", "points": "number of values N",
               "sigma": "true sigma [deg]", "coverage": "largest theta_r [deg], in/out of plane",
               "scale": "scale"}


# --------------------------------------------------------------------------------- rules
def _cov(cell: dict, name: str, method: str) -> float | None:
    p = cell["params"].get(name)
    return None if p is None else p[method]["coverage"]


def _fmt_cov(cell: dict, name: str, method: str) -> str:
    m = cell["params"][name][method]
    if m["coverage"] is None:
        return "no interval"
    return f"{m['covered']}/{m['with_interval']} = {m['coverage']:.2f} [{m['wilson'][0]:.2f}, {m['wilson'][1]:.2f}]"


def _point(coverage: str) -> str:
    """``0.85`` of ``17/20 = 0.85 [0.64, 0.95]``."""
    return coverage.split(" = ")[1].split(" [")[0] if " = " in coverage else coverage


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 2)


def rules(axes: dict[str, list[dict]]) -> list[dict[str, Any]]:
    """Checkable statements, each with the measured numbers behind it (empty where an axis
    was not run)."""
    out: list[dict[str, Any]] = []

    # 1. sigma near 0
    cells = axes.get("sigma", [])
    if cells:
        piled = [(c["settings"]["sigma"], c["params"]["sigma"]["piled_at_lower_bound"]) for c in cells]
        limit = [s for s, f in piled if f >= 0.5]
        x = max(limit) if limit else None
        above = [c for c in cells if x is None or c["settings"]["sigma"] > x]
        evidence = {f"sigma={c['settings']['sigma']:g}": {
            "piled_at_0_fraction": c["params"]["sigma"]["piled_at_lower_bound"],
            "MCMC_central_coverage": _fmt_cov(c, "sigma", "MCMC"),
            "MCMC_upper_limit_coverage": c["params"]["sigma"]["MCMC"]["upper_limit_coverage"],
            "least_squares_no_interval_fraction": c["params"]["sigma"]["ls_undetermined"],
            "least_squares_coverage": _fmt_cov(c, "sigma", "least squares"),
            "Laplace_coverage": _fmt_cov(c, "sigma", "Laplace"),
            "MCMC_failure_rate": c["sampler"]["failure_rate"]} for c in cells}
        if x is not None:
            text = (f"At true sigma <= {x:g} deg the posterior of sigma piles at 0 (gonio's flag in "
                    f"{100 * dict(piled)[x]:.0f} % of seeds at {x:g} deg): sigma is not identifiable; quote the "
                    "97.5 % upper limit, which held the truth in "
                    + ", ".join(f"{100 * c['params']['sigma']['MCMC']['upper_limit_coverage']:.0f} %"
                                f" (sigma={c['settings']['sigma']:g})" for c in cells if c['settings']['sigma'] <= x)
                    + f". From sigma = {min(c['settings']['sigma'] for c in above):g} deg up the flag fires in "
                    + (f"at most {100 * top:.0f} % of seeds." if (top := max(c['params']['sigma']['piled_at_lower_bound']
                                                                             for c in above)) else "no seed.")
                    if above else "")
        else:
            text = "The posterior of sigma piled at 0 in fewer than half the seeds at every sigma measured."
        out.append({"rule": "sigma near 0", "statement": text, "threshold_deg": x, "evidence": evidence})

    # 2. scale free without a standard
    cells = {c["settings"]["scale"]: c for c in axes.get("scale", [])}
    if "free" in cells:
        free = cells["free"]
        r = free["posterior_correlation"].get("rho-scale", {})
        ev = {k: {"rho_MCMC_coverage": _fmt_cov(c, "rho", "MCMC"),
                  "rho_width_median": c["params"]["rho"]["MCMC"]["width_median"],
                  "rho_least_squares_coverage": _fmt_cov(c, "rho", "least squares"),
                  "rho_Laplace_coverage": _fmt_cov(c, "rho", "Laplace"),
                  "rho_scale_correlation": c["posterior_correlation"].get("rho-scale"),
                  "rho_piled_at_upper_bound": c["params"]["rho"]["piled_at_upper_bound"],
                  "MCMC_failure_rate": c["sampler"]["failure_rate"], "steps_median": c["sampler"]["steps_median"]}
              for k, c in cells.items()}
        base_width = cells["fixed"]["params"]["rho"]["MCMC"]["width_median"] if "fixed" in cells else None
        text = (f"With scale free and no reference standard, rho and scale are correlated at a median |r| = "
                f"{r.get('median_abs', float('nan')):.3f} (|r| > 0.95 in {r.get('above_0.95', 0)} of {free['seeds']} "
                f"seeds); rho's 95 % interval is {free['params']['rho']['MCMC']['width_median']:.3g} wide (median)"
                + (f", {free['params']['rho']['MCMC']['width_median'] / base_width:.0f} times the calibrated fit's"
                   if base_width else "")
                + f", and the chain failed to converge within {free['sampler']['max_steps']} steps in "
                  f"{free['sampler']['failed']} of {free['seeds']} fits: rho is determined only through the small "
                  "rho^2 interreflection term; fix scale or measure a standard"
                + (f" (a 1 % standard: |r| = {cells['standard']['posterior_correlation']['rho-scale']['median_abs']:.3f}, "
                   f"rho width {cells['standard']['params']['rho']['MCMC']['width_median']:.3g}, failures "
                   f"{cells['standard']['sampler']['failed']} of {cells['standard']['seeds']})" if "standard" in cells
                   else "") + ".")
        out.append({"rule": "rho x scale without a standard", "statement": text, "evidence": ev})

    # 3. coverage below 0.9 along the design axes
    for axis, label in (("points", "N"), ("coverage", "theta_r max"), ("noise", "noise"), ("sigma", "sigma")):
        cells = axes.get(axis, [])
        if not cells:
            continue
        low = []
        for c in cells:
            for name in ("sigma", "rho"):
                for method in METHODS:
                    cov = _cov(c, name, method)
                    if cov is not None and cov < 0.9:
                        low.append({"cell": axis_label(axis, c["settings"]), "parameter": name, "method": method,
                                    "coverage": _fmt_cov(c, name, method),
                                    "below_nominal": c["params"][name][method]["wilson"][1] < 0.95,
                                    "bias_sd": c["params"][name][method]["bias_sd"]})
        if axis == "sigma":
            low = [x for x in low if float(x["cell"]) > 0]  # sigma = 0: rule 1
        cells_low = sorted({x["cell"] for x in low}, key=[axis_label(axis, c["settings"]) for c in cells].index)
        confirmed = {axis_label(axis, c["settings"]): c["confirmation"] for c in cells if "confirmation" in c}
        def entry(x: dict) -> str:
            return f"{x['parameter']} {x['method']} {_point(x['coverage'])}{'*' if x['below_nominal'] else ''}"

        text = (f"Along {AXIS_TITLES[axis]}, a 95 % interval held the truth in fewer than 90 % of seeds at: "
                + "; ".join(f"{cell} ({', '.join(sorted(entry(x) for x in low if x['cell'] == cell))})"
                            for cell in cells_low)
                + " (* where the Wilson 95 % interval of the coverage lies wholly below 0.95)."
                + ("".join(f" Re-measured at {cell} with {conf['fits']} least-squares fits of another noise stream: "
                           + ", ".join(f"{name} {p['covered']}/{p['with_interval']} = {p['coverage']:.2f} "
                                       f"[{p['wilson'][0]:.2f}, {p['wilson'][1]:.2f}] (rms z {p['rms_z']:.2f})"
                                       for name, p in conf["params"].items() if p["coverage"] is not None) + "."
                           for cell, conf in confirmed.items()))
                if low else f"Along {AXIS_TITLES[axis]}, every 95 % interval (sigma, rho; three methods) held the "
                            "truth in at least 90 % of seeds.")
        out.append({"rule": f"coverage below 0.9: {axis}", "statement": text, "cells_below": low,
                    "confirmations": confirmed})

    # 3b. precision along the design axes (what coverage cannot show: the width)
    for axis in ("points", "coverage"):
        cells = axes.get(axis, [])
        if not cells:
            continue
        widths = {axis_label(axis, c["settings"]): {name: c["params"][name]["MCMC"]["width_median"]
                                                    for name in ("sigma", "rho")} for c in cells}
        out.append({"rule": f"precision: {axis}",
                    "statement": f"Median 95 % width (MCMC) along {AXIS_TITLES[axis]}: " + "; ".join(
                        f"{cell}: sigma {w['sigma']:.3g} deg, rho {w['rho']:.3g}" for cell, w in widths.items()) + ".",
                    "widths": widths})

    # 4. where least squares / Laplace part from MCMC
    parted = []
    for axis, cells in axes.items():
        for c in cells:
            for name in c["free"]:
                for method in ("least squares", "Laplace"):
                    ratio = c["params"][name][method]["width_over_mcmc_median"]
                    cov, cov_m = _cov(c, name, method), _cov(c, name, "MCMC")
                    if (ratio is not None and not 0.8 <= ratio <= 1.25) or (
                            cov is not None and cov_m is not None and abs(cov - cov_m) > 0.1):
                        parted.append({"axis": axis, "cell": axis_label(axis, c["settings"]), "parameter": name,
                                       "method": method, "width_over_mcmc_median": ratio,
                                       "coverage": _fmt_cov(c, name, method), "MCMC": _fmt_cov(c, name, "MCMC")})
    out.append({"rule": "least squares and Laplace against MCMC",
                "statement": ("Cells where a Gaussian interval's median width differs from MCMC's by more than "
                              "a factor 1.25 or its coverage by more than 0.1: "
                              + ("; ".join(f"{p['axis']} {p['cell']} {p['parameter']} {p['method']} (width x"
                                           f"{_round(p['width_over_mcmc_median'])}, coverage "
                                           f"{p['coverage'].split(' [')[0]} vs MCMC {p['MCMC'].split(' [')[0]})"
                                           for p in parted) if parted else "none") + "."),
                "cells": parted})

    # 5. the sampler
    sampler = []
    for axis, cells in axes.items():
        for c in cells:
            s = c["sampler"]
            sampler.append({"axis": axis, "cell": axis_label(axis, c["settings"]), "failed": s["failed"],
                            "seeds": c["seeds"], "steps_median": s["steps_median"], "steps_max": s["steps_max"],
                            "warnings": {k: v for k, v in c["warnings"].items() if not k.startswith("polished")}})
    failing = [x for x in sampler if x["failed"]]
    steps = [x["steps_median"] for x in sampler]
    out.append({"rule": "sampler",
                "statement": (f"Median steps to convergence ranged {min(steps):.0f}-{max(steps):.0f} over the cells. "
                              + ("Fits not converged within the cap: " + "; ".join(
                                  f"{x['axis']} {x['cell']}: {x['failed']}/{x['seeds']}" for x in failing)
                                 if failing else "Every chain converged within the cap.")) if steps else "",
                "cells": sampler})
    return out


# ------------------------------------------------------------------------------- figures
def charts(axes: dict[str, list[dict]], stem: str) -> list[Path]:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullLocator

    names = [a for a in AXES if axes.get(a)]
    colours = {"least squares": "C1", "Laplace": "C2", "MCMC": "C0"}
    offsets = {"least squares": -0.22, "Laplace": 0.0, "MCMC": 0.22}
    fig = Figure(figsize=(15, 2.9 * len(names)), layout="constrained")
    grid = fig.subplots(len(names), 4, squeeze=False)
    for row, axis in zip(grid, names):
        cells = axes[axis]
        labels = [axis_label(axis, c["settings"]) for c in cells]
        x = np.arange(len(cells))
        for col, (quantity, name) in enumerate((("bias", "sigma"), ("bias", "rho"), ("coverage", "sigma"),
                                                ("coverage", "rho"))):
            ax = row[col]
            for method in METHODS:
                ys, lo, hi = [], [], []
                for c in cells:
                    m = c["params"][name][method]
                    if quantity == "bias":
                        y = m["bias_sd"]
                        e = m["bias_sd_se"] or 0.0
                        ys.append(np.nan if y is None else y)
                        lo.append(e), hi.append(e)
                    else:
                        y = m["coverage"]
                        ys.append(np.nan if y is None else y)
                        lo.append(0 if y is None else y - m["wilson"][0])
                        hi.append(0 if y is None else m["wilson"][1] - y)
                ax.errorbar(x + offsets[method], ys, yerr=[lo, hi], fmt="o", ms=4, capsize=2,
                            color=colours[method], label=method)
            if quantity == "bias":
                ax.axhline(0.0, color="k", lw=0.7)
                ax.set_ylabel(f"bias of {name} [posterior sd]", fontsize=8)
                ax.set_yscale("symlog", linthresh=1.0)
                low, high = ax.get_ylim()
                ax.set_ylim(min(low, -1.5), max(high, 1.5))
                ticks = [t for t in (-100, -30, -10, -3, -1, 0, 1, 3, 10, 30, 100)
                         if min(low, -1.5) <= t <= max(high, 1.5)]
                ax.set_yticks(ticks, [f"{t:g}" for t in ticks])
                ax.yaxis.set_minor_locator(NullLocator())
            else:
                ax.axhline(0.95, color="k", lw=0.7)
                ax.axhline(0.9, color="C3", lw=0.7, ls=":")
                ax.set_ylim(-0.03, 1.03)
                ax.set_ylabel(f"95 % coverage of {name}", fontsize=8)
            ax.set_xticks(x, labels, fontsize=7, rotation=20 if axis in ("coverage", "scale") else 0)
            ax.set_xlabel(AXIS_TITLES[axis], fontsize=8)
            ax.grid(alpha=0.3)
        row[0].legend(fontsize=7)
    fig.suptitle(f"{FIT_MODEL} fitted to {TRUTH_MODEL} data with relative Gaussian noise; base: "
                 f"{cell_key(BASE)}", fontsize=9)
    first = OUT / f"{stem}.png"
    fig.savefig(first, dpi=100)

    fig = Figure(figsize=(9, 2.6 * len(names)), layout="constrained")
    grid = fig.subplots(len(names), 2, squeeze=False)
    for row, axis in zip(grid, names):
        cells = axes[axis]
        x = np.arange(len(cells))
        labels = [axis_label(axis, c["settings"]) for c in cells]
        s = [c["sampler"] for c in cells]
        med = np.array([v["steps_median"] for v in s])
        row[0].errorbar(x, med, yerr=[med - [v["steps_p10"] for v in s], [v["steps_p90"] for v in s] - med],
                        fmt="o", capsize=3, color="C0", label="median, 10-90 %")
        row[0].plot(x, [v["steps_max"] for v in s], "v", color="C3", label="largest")
        row[0].axhline(s[0]["max_steps"], color="C3", lw=0.7, ls=":")
        row[0].set_yscale("log")
        row[0].set_ylabel("MCMC steps", fontsize=8)
        rate = np.array([v["failure_rate"] for v in s])
        row[1].errorbar(x, rate, yerr=[rate - [v["failure_wilson"][0] for v in s], [v["failure_wilson"][1] for v in s] - rate],
                        fmt="s", capsize=3, color="C3")
        row[1].set_ylim(-0.03, 1.03)
        row[1].set_ylabel("not converged (fraction)", fontsize=8)
        for ax in row:
            ax.set_xticks(x, labels, fontsize=7, rotation=20 if axis in ("coverage", "scale") else 0)
            ax.set_xlabel(AXIS_TITLES[axis], fontsize=8)
            ax.grid(alpha=0.3)
        row[0].legend(fontsize=7)
    fig.suptitle(f"gonio's default MCMC (cap {s[0]['max_steps']} steps), {FIT_MODEL}", fontsize=9)
    second = OUT / f"{stem}_sampler.png"
    fig.savefig(second, dpi=100)
    return [first, second]


# ---------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--axis", action="append", choices=list(AXES), help="run this axis only (repeatable)")
    parser.add_argument("--seeds", type=int, default=20, help="seeds per cell (default 20)")
    parser.add_argument("--max-steps", type=int, default=DEFAULT_CAP,
                        help=f"MCMC step cap (default {DEFAULT_CAP}; another cap writes validity_fits_capN.*)")
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 seeds, the ends of each axis, 2000 steps")
    parser.add_argument("--summary-only", action="store_true", help="no fits: the JSON and figures from the records")
    args = parser.parse_args(argv)
    global RECORDS
    seeds, max_steps = (3, 2000) if args.quick else (args.seeds, args.max_steps)
    stem = "validity_fits_quick" if args.quick else "validity_fits" if max_steps == DEFAULT_CAP else \
        f"validity_fits_cap{max_steps}"
    RECORDS = OUT / f"{stem}.jsonl"
    chosen = args.axis or list(AXES)
    plan: list[dict[str, Any]] = []
    for axis in chosen:
        cells = axis_cells(axis)
        if args.quick:
            cells = [cells[0], cells[-1]]
        for c in cells:
            if cell_key(c) not in [cell_key(p) for p in plan]:
                plan.append(c)
    plan.sort(key=lambda c: c["scale"] == "free")  # the slowest cell last
    records = [json.loads(line) for line in RECORDS.read_text().splitlines()] if RECORDS.exists() else []
    done = {(r["cell"], r["seed"]) for r in records if r["max_steps"] == max_steps}
    todo = [(c, s) for c in plan for s in range(seeds) if (cell_key(c), s) not in done]
    began, load = time.perf_counter(), os.getloadavg()
    print(f"{len(todo)} fits to do ({len(plan)} cells x {seeds} seeds, {len(done)} records present)", flush=True)
    if not args.summary_only:
        for k, (settings, seed) in enumerate(todo, start=1):
            record = run_fit(settings, seed, max_steps)
            save_cache()
            with RECORDS.open("a") as sink:
                sink.write(json.dumps(record) + "\n")
            records.append(record)
            elapsed = time.perf_counter() - began
            print(f"[{k}/{len(todo)}] {record['cell']} seed {seed}: {record['seconds']:.1f} s, "
                  f"{record['sampler']['steps']} steps{'' if record['sampler']['converged'] else ' NOT CONVERGED'} "
                  f"(elapsed {elapsed / 60:.1f} min)", flush=True)
    wall = time.perf_counter() - began
    by_cell: dict[str, list[dict]] = {}
    for r in records:
        if r["max_steps"] == max_steps:
            by_cell.setdefault(r["cell"], []).append(r)
    summaries = {key: summarise_cell(rs) for key, rs in by_cell.items()}
    confirmations_path = OUT / f"{stem}_confirm.jsonl"
    confirmations = {}
    if confirmations_path.exists():
        confirmations = {c["cell"]: c for c in map(json.loads, confirmations_path.read_text().splitlines())}
    for key, summary in summaries.items():
        summary["noise_free_shift_stderr"] = noise_free(summary["settings"])
        if summary["seeds"] >= seeds and needs_confirmation(summary) and not args.quick:
            if key not in confirmations:
                print(f"confirming {key} with {CONFIRM_FITS} least-squares fits", flush=True)
                confirmations[key] = {"cell": key, **confirm(summary["settings"])}
                with confirmations_path.open("a") as sink:
                    sink.write(json.dumps(confirmations[key]) + "\n")
            summary["confirmation"] = confirmations[key]
    save_cache()
    axes = {axis: [summaries[cell_key(c)] for c in axis_cells(axis) if cell_key(c) in summaries] for axis in AXES}
    missing = {axis: [axis_label(axis, c) for c in axis_cells(axis) if cell_key(c) not in summaries
                      or summaries[cell_key(c)]["seeds"] < seeds] for axis in AXES}
    payload = {
        "benchmark": "validity_fits",
        "command": "python benchmarks/validity_fits.py" + (" --quick" if args.quick else "")
                   + (f" --max-steps {max_steps}" if not args.quick and max_steps != DEFAULT_CAP else "")
                   + "".join(f" --axis {a}" for a in args.axis or [])
                   + (f" --seeds {seeds}" if not args.quick and seeds != 20 else ""),
        "truth_model": TRUTH_MODEL, "fit_model": FIT_MODEL, "rho": RHO, "incidences": INCIDENCES,
        "out_of_plane_azimuths": AZIMUTHS, "standard_relative_sd": STANDARD, "base": BASE,
        "axes_definition": AXES, "seeds_per_cell": seeds, "max_steps": max_steps, "mcmc": mcmc_design(),
        "methods": {"least squares": "optimum +- 1.96 standard errors of (J^T J)^-1",
                    "Laplace": "the least-squares Gaussian truncated to the support: its 2.5/50/97.5 % quantiles",
                    "MCMC": "posterior 2.5/50/97.5 % percentiles"},
        "bias_unit": "MCMC posterior sd of the same fit",
    "noise_free_shift_stderr": "per cell: least squares of the fitted model to the exact model's noise-free values "
                               "(the cell's uncertainties), (value - truth) / standard error",
        "axes": axes, "missing": {a: m for a, m in missing.items() if m},
        "rules": rules(axes),
        "records": len([r for r in records if r["max_steps"] == max_steps]),
        "fit_seconds_total": float(sum(r["seconds"] for r in records if r["max_steps"] == max_steps)),
        "this_invocation": {"wall_seconds": wall, "fits": 0 if args.summary_only else len(todo),
                            "load_average_start": load, "load_average_end": os.getloadavg()},
        "machine": machine(),
    }
    previous = OUT / f"{stem}.json"
    if args.summary_only and previous.exists():  # keep the timing of the invocation that ran the fits
        payload["this_invocation"] = json.loads(previous.read_text()).get("this_invocation", payload["this_invocation"])
    path = write_json(stem, payload)
    figures = charts(axes, stem)
    for rule in payload["rules"]:
        print("-", rule["statement"])
    print(f"wrote {path}, {', '.join(str(f) for f in figures)} ({wall / 60:.1f} min)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

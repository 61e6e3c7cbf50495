"""Every CUReT sample x every candidate of ``gonio curet fit``, as one batch on 2 workers.

Data: the CUReT BRDF database, K. J. Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink,
"Reflectance and texture of real-world surfaces", ACM TOG 18(1), 1999 (61 samples, 205
geometries each, RGB-averaged absolute BRDF [1/sr]).

The fits are those of ``gonio fit-batch --curet all --workers 2`` (gonio.fit_many with the
CUReT loaders of gonio.cli.fit_batch): ``gonio curet fit``'s noise model (relative
uncertainty from the scatter about a smooth Koenderink-van Doorn series, all 205
geometries kept), its candidates (gonio.cli.curet.DEFAULT_CANDIDATES), a fitted absolute
jitter, least squares then MCMC at gonio's defaults, each task seeded from base seed 0 and
its id (gonio.batch.task_seed).  The batch folder is benchmarks/_build/curet-batch/ (not
tracked); a re-run skips the finished fits.  Per sample, the model ``gonio curet fit``
would choose comes from gonio.fitting.compare_models under the same likelihood (noise
model plus fitted absolute jitter), as that command computes it.

Writes docs/curet-all.md (one row per sample, a per-model table, a summary), the chart
docs/benchmarks/curet_batch.png and docs/benchmarks/curet_batch.json.

Also, once (cached beside the batch folder): samples 1-10 fitted again with 1 and with 2
workers in fresh folders, for the speed-up and the check that the numbers do not change.
Fit folders take about 15 MB each (3.6 GB for the batch, mostly ``posterior.nc``); the
sub-batches are removed once timed.

Run: ``python benchmarks/curet_batch.py`` (about 3 minutes of fits on 2 cores plus one for
the 1-vs-2-worker check and the comparisons; seconds when everything is found finished,
which rewrites the page from the finished batch).
"""
from __future__ import annotations

import argparse
import functools
import json
import math
import os
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, mcmc_design, write_json  # noqa: E402

BUILD = ROOT / "benchmarks" / "_build" / "curet-batch"
#: Records of each run of this script's batch (wall time, load), beside the batch folder.
RUNS = ROOT / "benchmarks" / "_build" / "curet-batch-runs.json"
#: gonio curet's model comparison per sample (least squares + Laplace evidence), cached.
COMPARISONS = ROOT / "benchmarks" / "_build" / "curet-batch-comparisons.json"
DOCS = ROOT / "docs"
PAGE = DOCS / "curet-all.md"
CHART = DOCS / "benchmarks" / "curet_batch.png"
WORKERS = 2
SEED = 0
COMMAND = "gonio fit-batch --curet all --out benchmarks/_build/curet-batch --workers 2"
#: The paper's full model with the interreflection term at full weight (docs/curet-fits.md, "ir_weight").
REFERENCE_MODEL = "oren-nayar:ir_weight=1"


# ---------------------------------------------------------------------- the batch
class LoadSampler:
    """The 1-minute load average, sampled every ``period`` seconds in a thread."""

    def __init__(self, period: float = 10.0):
        self.period = period
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while True:
            self.samples.append(os.getloadavg()[0])
            if self._stop.wait(self.period):
                return

    def __enter__(self) -> "LoadSampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.samples.append(os.getloadavg()[0])

    def summary(self) -> dict[str, float]:
        return {"mean": statistics.fmean(self.samples), "max": max(self.samples), "n": len(self.samples)}


def batch_inputs(samples: Sequence[int] | None = None) -> dict[str, Any]:
    """One loader per CUReT sample, named ``curet-NN``, as ``gonio fit-batch --curet`` builds them."""
    from gonio.cli.curet import load_curet
    from gonio.cli.fit_batch import curet_input

    numbers = [int(n) for n in load_curet().sample_numbers]
    if samples is not None:
        numbers = [n for n in numbers if n in set(samples)]
    return {f"curet-{n:02d}": functools.partial(curet_input, None, n, None) for n in numbers}


def batch_settings():
    """``gonio fit-batch --curet``'s settings: its defaults with the absolute jitter of ``gonio curet fit``."""
    from gonio.batch import BatchSettings

    return BatchSettings(jitter="absolute")


def run_batch(workers: int = WORKERS, out: Path = BUILD, samples: Sequence[int] | None = None) -> dict[str, Any]:
    """Run (or resume) the batch; return the rows and a record of this run (wall time, load)."""
    import gonio
    from gonio.cli.curet import DEFAULT_CANDIDATES

    def progress(done: int, total: int, row: Mapping[str, Any]) -> None:
        what = "skipped" if row.get("status") == "skipped" else (row.get("verdict") or "FAILED")
        print(f"[{done}/{total}] {row['task_id']}: {what} ({time.perf_counter() - start:.0f} s)", flush=True)

    start = time.perf_counter()
    with LoadSampler() as load:
        batch = gonio.fit_many(batch_inputs(samples), list(DEFAULT_CANDIDATES), out, workers=workers, seed=SEED,
                               settings=batch_settings(), progress=progress,
                               announce=lambda text: print(text, flush=True))
    wall = time.perf_counter() - start
    record = {"workers": workers, "out": str(Path(out).relative_to(ROOT)), "tasks": len(batch.rows),
              "fitted": len(batch.rows) - len(batch.skipped), "skipped": len(batch.skipped),
              "failed": len(batch.failed), "wall_seconds": wall,
              "task_seconds_fitted": sum(r["wall_seconds"] or 0.0 for r in batch.rows
                                         if r["task_id"] not in set(batch.skipped)),
              "load_average_1min": load.summary(), "cpu_count": os.cpu_count(),
              "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    return {"rows": batch.rows, "record": record}


def append_run(record: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Add a run record to :data:`RUNS` and return every record."""
    runs = json.loads(RUNS.read_text()) if RUNS.is_file() else []
    runs.append(dict(record))
    RUNS.parent.mkdir(parents=True, exist_ok=True)
    RUNS.write_text(json.dumps(runs, indent=1) + "\n")
    return runs


def worker_comparison(samples: Sequence[int], base: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The same sub-batch with 1 and with 2 workers, each in a fresh folder: wall times, and
    whether their numbers equal those of the main batch (``base``: rows by task id).

    A sub-batch folder left by an interrupted call is started again, so that every fit is
    timed; both are removed once compared (the main batch holds the same fits).
    """
    import shutil

    runs = {}
    same = True
    for workers in (1, 2):
        out = BUILD.parent / "curet-batch-workers" / str(workers)
        if out.exists() and (out / "batch.json").is_file():
            shutil.rmtree(out)  # this script's own sub-batch: start it again so that every fit is timed
        result = run_batch(workers, out, samples)
        runs[workers] = result["record"]
        for row in result["rows"]:
            reference = base.get(row["task_id"])
            same &= reference is not None and _same_numbers(row, reference)
    shutil.rmtree(BUILD.parent / "curet-batch-workers")
    return {"samples": list(samples), "tasks": runs[1]["tasks"], "runs": {str(k): v for k, v in runs.items()},
            "speed_up": runs[1]["wall_seconds"] / runs[2]["wall_seconds"], "same_numbers_as_main_batch": same}


def _same_numbers(row: Mapping[str, Any], other: Mapping[str, Any]) -> bool:
    """Equal verdict, chi-square and posterior statistics (wall times aside)."""
    if row["status"] != other["status"] or row.get("verdict") != other.get("verdict"):
        return False
    if not _equal(row.get("chi2"), other.get("chi2")):
        return False
    return all(_equal(stats.get(k), other["parameters"].get(name, {}).get(k))
               for name, stats in row["parameters"].items() for k in stats)


def _equal(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is b
    return a == b or (math.isnan(float(a)) and math.isnan(float(b)))


# ---------------------------------------------------------------------- gonio curet's comparison
def _compare_one(number: int) -> dict[str, Any]:
    """gonio curet fit's model comparison of one sample (least squares, Laplace evidence), with
    the sample's facts; one BLAS thread."""
    import numpy as np
    from threadpoolctl import threadpool_limits

    from gonio.cli.curet import DEFAULT_CANDIDATES, curet_dataset, load_curet
    from gonio.fitting import compare_models
    from gonio.sample_specs import split_model_spec

    data = load_curet()
    dataset, noise = curet_dataset(data, number)
    candidates = [split_model_spec(spec)[:2] for spec in DEFAULT_CANDIDATES]
    with threadpool_limits(limits=1, user_api="blas"):
        comparison = compare_models(dataset, candidates, jitter="absolute")
    labels = {comparison_label(spec): spec for spec in DEFAULT_CANDIDATES}
    sample = data.sample(number)
    return {"number": int(number), "name": sample.name, "n_data": int(dataset.n),
            "negative": int(np.count_nonzero(sample.brdf < 0)), "noise_relative": float(noise.relative),
            "pi_median": float(math.pi * np.median(sample.brdf)),
            "chosen": labels[comparison.chosen], "chosen_verdict": comparison.chosen_verdict,
            "chosen_adequate": bool(comparison.chosen_adequate), "reason": comparison.reason,
            "comparison": {labels[row["label"]]: {"verdict": row["verdict"], "redchi": float(row["redchi"]),
                                                  "log_evidence": float(row["log_evidence"]),
                                                  "lack_of_fit_p": _float(row["lack_of_fit_p"])}
                           for row in comparison.rows}}


def comparison_label(spec: str) -> str:
    """The label gonio's comparison gives a model spec (``oren-nayar (ir_weight=1)``)."""
    from gonio.fitting.selection import candidate_label
    from gonio.sample_specs import split_model_spec

    name, fixed, _ = split_model_spec(spec)
    return candidate_label(name, fixed)


def _float(value: Any) -> float | None:
    return None if value is None or not math.isfinite(float(value)) else float(value)


def comparisons(numbers: Sequence[int], workers: int = WORKERS) -> dict[int, dict[str, Any]]:
    """gonio curet's comparison of every sample, cached in :data:`COMPARISONS` (keyed by the
    candidates, so a change of them recomputes)."""
    from joblib import Parallel, delayed

    from gonio.cli.curet import DEFAULT_CANDIDATES

    key = ",".join(DEFAULT_CANDIDATES)
    cached = json.loads(COMPARISONS.read_text()) if COMPARISONS.is_file() else {}
    found = {int(k): v for k, v in cached.get("samples", {}).items()} if cached.get("candidates") == key else {}
    todo = [n for n in numbers if n not in found]
    if todo:
        print(f"comparing the candidates on {len(todo)} sample(s) ...", flush=True)
        for record in Parallel(n_jobs=min(workers, len(todo)))(delayed(_compare_one)(n) for n in todo):
            found[record["number"]] = record
        COMPARISONS.write_text(json.dumps({"candidates": key, "samples": {str(k): v for k, v in sorted(found.items())}},
                                          indent=1) + "\n")
    return {n: found[n] for n in numbers}


# ---------------------------------------------------------------------- the table
def _result_facts(row: Mapping[str, Any]) -> dict[str, Any]:
    """Lack-of-fit p, jitter over the stated noise, MCMC steps and the validity note of a saved fit."""
    path = BUILD / row["task_id"] / "result.json"
    if row["status"] != "ok" or not path.is_file():
        return {}
    data = json.loads(path.read_text())
    adequacy = data.get("adequacy") or {}
    lack = adequacy.get("lack_of_fit") or {}
    validity = data.get("validity") or {}
    return {"lack_of_fit_p": lack.get("p"), "alpha": adequacy.get("alpha"),
            "extra_noise_ratio": adequacy.get("extra_noise_ratio"),
            "mcmc_steps": (data.get("mcmc") or {}).get("n_steps"),
            "validity_bias_sd": validity.get("bias_sd") or {}}


def sample_table(rows: Sequence[Mapping[str, Any]], compared: Mapping[int, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One record per sample: its facts, gonio curet's choice, and its fits by model spec."""
    by_input: dict[str, dict[str, Any]] = {}
    for row in rows:
        fit = {k: row.get(k) for k in ("task_id", "status", "verdict", "chi2", "dof", "redchi", "converged",
                                       "r_hat_max", "ess_bulk_min", "wall_seconds", "failure", "seed")}
        fit["parameters"] = {name: dict(stats) for name, stats in row["parameters"].items()}
        fit.update(_result_facts(row))
        by_input.setdefault(row["input"], {})[row["model"]] = fit
    table = []
    for number, facts in compared.items():
        table.append({**facts, "fits": by_input.get(f"curet-{number:02d}", {})})
    return table


# ---------------------------------------------------------------------- numbers for the page
#: Short verdict marks of the per-sample table.
MARKS = {"adequate": "A", "noise understated": "N", "inadequate": "I"}
#: Smallest bulk effective sample size flagged as too few (Vehtari et al. 2021: 100 per chain, 4 chains).
ESS_FLAG = 400.0
#: Relative noise above which the smooth series leaves a large scatter (stated in the summary).
LARGE_NOISE = 0.2


def _bounds(spec: str, name: str) -> tuple[float, float]:
    from gonio import models

    params = {p.name: p for p in models.get(spec.split(":", 1)[0]).params}
    return tuple(params[name].bounds) if name in params else (-math.inf, math.inf)


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None or not math.isfinite(float(x)):
        return "-"
    x = float(x)
    if abs(x) >= 100 or (abs(x) < 1e-3 and x != 0):
        return f"{x:.3g}"
    return f"{x:.{digits}g}"


def bound_note(stats: Mapping[str, float], bounds: tuple[float, float]) -> str:
    """"unconstrained", "at upper bound", "at lower bound" or "" (as docs/curet-fits.md marks intervals)."""
    lo, hi = bounds
    low, high = stats.get("p2_5"), stats.get("p97_5")
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return ""
    width = high - low
    if math.isfinite(hi) and math.isfinite(lo) and width > 0.8 * (hi - lo):
        return "unconstrained"
    if math.isfinite(hi) and hi - high < 0.05 * width:
        return "at upper bound"
    if math.isfinite(lo) and low - lo < 0.05 * width:
        return "at lower bound"
    return ""


def interval(fit: Mapping[str, Any] | None, spec: str, name: str) -> str:
    """``median [p2_5, p97_5]`` of a parameter of a fit, with a bound note; "-" without it."""
    stats = (fit or {}).get("parameters", {}).get(name)
    if not stats:
        return "-"
    text = f"{_fmt(stats.get('median'))} [{_fmt(stats.get('p2_5'))}, {_fmt(stats.get('p97_5'))}]"
    note = bound_note(stats, _bounds(spec, name))
    return f"{text} ({note})" if note else text


def fit_flags(fit: Mapping[str, Any], rhat_limit: float = 1.01) -> list[str]:
    """Why a fit's numbers need care: failure, no convergence, R-hat, ESS."""
    if fit.get("status") != "ok":
        return ["failed"]
    flags = []
    if fit.get("converged") is False:
        flags.append("not converged")
    r_hat = fit.get("r_hat_max")
    if r_hat is not None and math.isfinite(r_hat) and r_hat > rhat_limit:
        flags.append(f"R-hat {r_hat:.3f}")
    ess = fit.get("ess_bulk_min")
    if ess is not None and math.isfinite(ess) and ess < ESS_FLAG:
        flags.append(f"ESS {ess:.0f}")
    return flags


def _quantiles(values: Sequence[float], qs: Sequence[float] = (0.1, 0.25, 0.5, 0.75, 0.9)) -> list[float]:
    import numpy as np

    return [float(q) for q in np.quantile(np.asarray(values, float), qs)] if values else [math.nan] * len(qs)


def summarise(table: Sequence[Mapping[str, Any]], candidates: Sequence[str]) -> dict[str, Any]:
    """Counts per model, choices, and the sigma distribution over samples."""
    per_model = {}
    for spec in candidates:
        fits = [s["fits"][spec] for s in table if spec in s["fits"]]
        ok = [f for f in fits if f.get("status") == "ok"]
        per_model[spec] = {
            "label": comparison_label(spec),
            "fits": len(fits), "ok": len(ok), "failed": len(fits) - len(ok),
            **{verdict: sum(f.get("verdict") == verdict for f in ok) for verdict in MARKS},
            "chosen": sum(s["chosen"] == spec for s in table),
            "chosen_adequate": sum(s["chosen"] == spec and s["chosen_adequate"] for s in table),
            "redchi_median": statistics.median([f["redchi"] for f in ok]) if ok else math.nan,
            "not_converged": sum(f.get("converged") is False for f in ok),
            "rhat_flagged": sum(any(x.startswith("R-hat") for x in fit_flags(f)) for f in ok),
            "ess_flagged": sum(any(x.startswith("ESS") for x in fit_flags(f)) for f in ok),
            "formula_checked": sum(bool(f.get("validity_bias_sd")) for f in ok),
            "formula_bias_over_1sd": sum(any(v is not None and abs(v) > 1.0 for v in
                                             (f.get("validity_bias_sd") or {}).values()) for f in ok),
        }
    sigma = {}
    for key, pick in (("reference", lambda s: REFERENCE_MODEL), ("chosen", lambda s: s["chosen"])):
        values, at_lower, at_upper = [], 0, 0
        for s in table:
            spec = pick(s)
            fit = s["fits"].get(spec) or {}
            stats = fit.get("parameters", {}).get("sigma")
            if fit.get("status") != "ok" or not stats:
                continue
            values.append(stats["median"])
            note = bound_note(stats, _bounds(spec, "sigma"))
            at_lower += note == "at lower bound"
            at_upper += note == "at upper bound"
        sigma[key] = {"samples": len(values), "quantiles_10_25_50_75_90": _quantiles(values),
                      "min": min(values) if values else math.nan, "max": max(values) if values else math.nan,
                      "at_lower_bound": at_lower, "at_upper_bound": at_upper}
    any_adequate = sum(any(f.get("verdict") == "adequate" for f in s["fits"].values()) for s in table)
    any_passing = sum(any(f.get("verdict") in ("adequate", "noise understated") for f in s["fits"].values())
                      for s in table)
    failures = [(s["number"], spec, f.get("failure") or "") for s in table for spec, f in s["fits"].items()
                if f.get("status") != "ok"]
    missing = [(s["number"], spec) for s in table for spec in candidates if spec not in s["fits"]]
    lack = [f["lack_of_fit_p"] for s in table for f in s["fits"].values() if f.get("lack_of_fit_p") is not None]
    alphas = {f["alpha"] for s in table for f in s["fits"].values() if f.get("alpha") is not None}
    return {"samples": len(table), "fits": sum(len(s["fits"]) for s in table), "per_model": per_model,
            "samples_with_an_adequate_fit": any_adequate, "samples_with_a_passing_fit": any_passing,
            "chosen_adequate": sum(bool(s["chosen_adequate"]) for s in table), "sigma": sigma,
            "failures": failures, "missing": missing, "lack_of_fit_p_max": max(lack) if lack else None,
            "alpha": max(alphas) if alphas else None,
            "large_noise_samples": [s["number"] for s in table if s["noise_relative"] > LARGE_NOISE],
            "noise_relative_quantiles_10_50_90": _quantiles([s["noise_relative"] for s in table], (0.1, 0.5, 0.9))}


# ---------------------------------------------------------------------- the page
def _q(values: Sequence[float], digits: int = 3) -> str:
    """``median (quartiles a-b; 10-90 % c-d)`` of quantiles 10, 25, 50, 75, 90 %."""
    q10, q25, q50, q75, q90 = values
    return f"{_fmt(q50, digits)} (quartiles {_fmt(q25, digits)}-{_fmt(q75, digits)}; 10-90 % {_fmt(q10, digits)}-{_fmt(q90, digits)})"


def sample_row(sample: Mapping[str, Any], candidates: Sequence[str]) -> str:
    """One line of the per-sample table."""
    chosen = sample["chosen"]
    fit = sample["fits"].get(chosen)
    verdict = fit.get("verdict") if fit and fit.get("status") == "ok" else "failed"
    cells = []
    for spec in candidates:
        f = sample["fits"].get(spec)
        if f is None:
            cells.append("not run")
        elif f.get("status") != "ok":
            cells.append("failed")
        else:
            cells.append(f"{_fmt(f['redchi'])} {MARKS.get(f.get('verdict'), '?')}")
    flags = [f"{comparison_label(spec)}: {', '.join(fit_flags(f))}" for spec, f in sample["fits"].items()
             if fit_flags(f)]
    if sample.get("negative"):
        flags.append(f"{sample['negative']} negative value(s), kept")
    return (f"| {sample['number']} | {sample['name']} | {sample['noise_relative']:.3f} | {comparison_label(chosen)} | "
            f"{verdict} | {interval(fit, chosen, 'rho')} | {interval(fit, chosen, 'sigma')} | "
            f"{interval(sample['fits'].get(REFERENCE_MODEL), REFERENCE_MODEL, 'sigma')} | "
            f"{' / '.join(cells)} | {'; '.join(flags) or '-'} |")


def model_row(spec: str, counts: Mapping[str, Any]) -> str:
    """One line of the per-model table."""
    formula = (f"{counts['formula_bias_over_1sd']} of {counts['formula_checked']}" if counts["formula_checked"]
               else "-")
    return (f"| {counts['label']} | {counts['ok']} | {counts['adequate']} | {counts['noise understated']} | "
            f"{counts['inadequate']} | {counts['failed']} | {counts['chosen']} | {_fmt(counts['redchi_median'])} | "
            f"{counts['not_converged']} | {counts['rhat_flagged']} | {counts['ess_flagged']} | {formula} |")


def adequacy_line(summary: Mapping[str, Any], per_model: Mapping[str, Mapping[str, Any]]) -> str:
    """The summary's first statement: which models describe which samples adequately."""
    counts = "; ".join(f"{m['label']} {m['adequate']} of {m['ok']}" for m in per_model.values())
    text = (f"* **Adequate descriptions**: {counts}. {summary['samples_with_an_adequate_fit']} of "
            f"{summary['samples']} samples have an adequate candidate, {summary['samples_with_a_passing_fit']} one "
            f"that is adequate or only understates the noise; gonio curet's chosen model is adequate on "
            f"{summary['chosen_adequate']}.")
    if summary["samples_with_a_passing_fit"] == 0 and summary.get("lack_of_fit_p_max") is not None:
        text += (f" **No candidate describes any sample adequately**: on every fit a flexible reciprocal series "
                 f"follows structure the model misses (largest lack-of-fit p {summary['lack_of_fit_p_max']:.1g}"
                 + (f", threshold {summary['alpha']:g}" if summary.get("alpha") is not None else "")
                 + "), so every chosen model is the best by evidence, not a model that explains the data, and "
                 "its parameters are effective ones.")
    return text


def markdown(table: Sequence[Mapping[str, Any]], context: Mapping[str, Any]) -> str:
    """docs/curet-all.md from the per-sample table (:func:`sample_table`) and the run's context.

    ``context`` holds ``candidates`` (model specs), ``summary`` (:func:`summarise`), ``mcmc``
    (the MCMC design), ``credit``, ``run`` (the record of the run that fitted the batch),
    ``workers`` (:func:`worker_comparison`'s record, or None) and ``rhat_limit``.
    """
    candidates = list(context["candidates"])
    summary = context["summary"]
    labels = [comparison_label(spec) for spec in candidates]
    run = context["run"]
    per_model = summary["per_model"]
    reference = comparison_label(REFERENCE_MODEL)
    sigma_ref, sigma_chosen = summary["sigma"]["reference"], summary["sigma"]["chosen"]
    ranked = sorted((s for s in table if (s["fits"].get(REFERENCE_MODEL) or {}).get("status") == "ok"
                     and s["noise_relative"] <= LARGE_NOISE),
                    key=lambda s: s["fits"][REFERENCE_MODEL]["redchi"])
    closest = ", ".join(f"{s['number']} {s['name']} ({_fmt(s['fits'][REFERENCE_MODEL]['redchi'])})" for s in ranked[:5])
    farthest = ", ".join(f"{s['number']} {s['name']} ({_fmt(s['fits'][REFERENCE_MODEL]['redchi'])})"
                         for s in ranked[::-1][:5])
    load = run["load_average_1min"]
    missing = summary["missing"]
    lines = [
        "# Every CUReT sample fitted with every candidate of `gonio curet fit`",
        "",
        "Generated by `python benchmarks/curet_batch.py` (numbers below are from that run; the prose",
        "is part of the script and quotes the computed values). The four samples studied in depth,",
        "with figures, the extra Torrance-Sparrow candidate and the noise-model dependence, are in",
        "[curet-fits.md](curet-fits.md); this page is the same fit over the whole database, in one table.",
        "",
        f"{context['credit']}. {len(table)} samples x 205 geometries, BRDF [1/sr] averaged over",
        "the red, green and blue channels, read by `gonio.curet`.",
        "",
        "## How the numbers were made",
        "",
        "```console",
        f"$ {COMMAND}",
        "```",
        "",
        f"The script runs this batch through `gonio.fit_many` ({run['workers']} joblib workers, the CUReT",
        "loaders and settings of `gonio fit-batch --curet`); the command above resumes the same folder",
        "and finds every fit finished. Each task (sample x model) is one `gonio fit` result folder in",
        "`benchmarks/_build/curet-batch/` (not tracked; `gonio report FOLDER` draws its report).",
        "",
        "* **Candidates** (`gonio curet fit`'s default): " + ", ".join(f"`{c}`" for c in candidates)
        + ": Lambert, the qualitative Oren-Nayar model (eq 36), and the full model (eq 33-35) with the",
        "  interreflection term at full weight (the paper's model) and with `ir_weight` free in [0, 1].",
        "* **Noise model** (`gonio curet`'s, docs/curet-fits.md \"Uncertainties\"): a relative uncertainty",
        "  s per sample, from the scatter of the data about a smooth Koenderink-van Doorn series of",
        "  order 6 (30 amplitudes), sigma_i = sqrt((s f_series,i)^2 + (0.001/sqrt 12)^2), independent of",
        "  the models under test; s errs on the large side, so a reduced chi-square near 1 means *as good",
        "  as the best smooth description the data support*. All 205 geometries are kept (negative",
        "  values too: they are legitimate noisy values of dark samples; no near-specular exclusion).",
        "  Every fit has a fitted absolute `jitter` [1/sr] in quadrature (`--jitter absolute`, as",
        "  `gonio curet fit`), so that intervals widen where a model misfits.",
        f"* **Fits**: least squares, then MCMC with {context['mcmc']}. Each task's seed is",
        f"  `gonio.batch.task_seed({SEED}, TASK_ID)` (base seed {SEED}), so the numbers do not depend on",
        "  the worker count or the order the fits finish.",
        "* **Chosen model**: the one `gonio curet fit` chooses, by `gonio.fitting.compare_models` under",
        "  the same likelihood (noise model plus fitted jitter, at the posterior mode): the adequate",
        "  candidates within 1 ln unit of the best adequate Laplace evidence, then the fewest",
        "  parameters; when none is adequate, the best by evidence, marked as explaining nothing.",
        "  Its rho and sigma below are the MCMC medians of that model's batch fit.",
        "* **Verdict** (docs/fitting.md, \"Three verdicts\"): *adequate*; *noise understated* (the",
        "  model follows the data but the scatter exceeds the stated noise); *inadequate* (a flexible",
        "  reciprocal series follows structure the model misses: the lack-of-fit test, independent of",
        "  the noise's size).",
        "",
        "## What the numbers mean",
        "",
        "rho and sigma are *effective* parameters: the albedo and the facet-slope standard deviation",
        "[deg] with which the model describes the sample's BRDF at these 205 geometries. Where the",
        "model is inadequate they are that model's best description, not a measurement of the surface:",
        "many CUReT samples are not rough-diffuse surfaces (fabrics, fur, foils, leaves, samples with a",
        "specular sheen), and the camera averages an image region over the sample's texture, so what",
        "is fitted is the BRDF of a textured patch, re-posed for every geometry. The 95 % intervals",
        "are posterior intervals under the noise model plus jitter; they hold neither the model's",
        "error nor the choice of noise shape (docs/curet-fits.md estimates that component for four",
        "samples). A sigma interval reaching the bound 0 means the data do not distinguish the model",
        "from a smooth (Lambertian-like) surface. Intervals are marked (at lower bound), (at upper",
        "bound) or (unconstrained, wider than 80 % of the parameter's range) as in docs/curet-fits.md.",
        "",
        "## Summary",
        "",
        adequacy_line(summary, per_model),
        f"* **{summary['fits']} fits** of {len(candidates)} models on {summary['samples']} samples: "
        f"{sum(m['ok'] for m in per_model.values())} finished, {sum(m['failed'] for m in per_model.values())} "
        f"failed{f', {len(missing)} not run' if missing else ''}.",
        "* **Chosen by gonio curet's rule**: "
        + "; ".join(f"{m['label']} on {m['chosen']}" for m in per_model.values()) + " samples.",
        "* **Reduced chi-square** (median over samples): "
        + "; ".join(f"{m['label']} {_fmt(m['redchi_median'])}" for m in per_model.values())
        + f". Among the samples with s <= {LARGE_NOISE:g} (below), the lowest reduced chi-square of {reference}: "
        f"{closest}; the highest: {farthest}.",
        f"* **sigma over samples**, {reference} (every sample): median {_q(sigma_ref['quantiles_10_25_50_75_90'])} "
        f"deg, range {_fmt(sigma_ref['min'])}-{_fmt(sigma_ref['max'])} deg; the interval reaches the bound 0 on "
        f"{sigma_ref['at_lower_bound']} samples. The chosen model's sigma ({sigma_chosen['samples']} samples where "
        f"it has one): median {_q(sigma_chosen['quantiles_10_25_50_75_90'])} deg; its interval reaches the "
        f"bound 90 deg on {sigma_chosen['at_upper_bound']} and 0 on {sigma_chosen['at_lower_bound']} of them.",
        f"* **Estimated noise** s over samples: median {_fmt(summary['noise_relative_quantiles_10_50_90'][1])}, "
        f"10-90 % {_fmt(summary['noise_relative_quantiles_10_50_90'][0])}-"
        f"{_fmt(summary['noise_relative_quantiles_10_50_90'][2])}. {len(summary['large_noise_samples'])} samples "
        f"have s above {LARGE_NOISE:g}"
        + (f" ({', '.join(str(n) for n in summary['large_noise_samples'])})" if summary["large_noise_samples"] else "")
        + ": there the smooth series itself leaves a large scatter, and a reduced chi-square near or below 1 says "
        "only that a model misfits no more than that; the lack-of-fit test of the verdict does not depend on s.",
        f"* **Chains**: {sum(m['not_converged'] for m in per_model.values())} not converged, "
        f"{sum(m['rhat_flagged'] for m in per_model.values())} with R-hat > {context['rhat_limit']:g}, "
        f"{sum(m['ess_flagged'] for m in per_model.values())} with a bulk ESS below {ESS_FLAG:.0f}.",
        f"* **Wall time**: {run['fitted']} fits in {run['wall_seconds'] / 60:.1f} min on {run['workers']} workers "
        f"({run['task_seconds_fitted'] / 60:.1f} min summed over the fits' own wall times), 1-minute load "
        f"average {load['mean']:.2f} on average and {load['max']:.2f} at most on {run['cpu_count']} cores "
        "(the machine was shared).",
        "",
        "## Per model",
        "",
        "| model | fitted | adequate | noise understated | inadequate | failed | chosen | median redchi | not converged "
        f"| R-hat > {context['rhat_limit']:g} | ESS < {ESS_FLAG:.0f} | formula error > 1 sd |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [model_row(spec, per_model[spec]) for spec in candidates]
    lines += [
        "",
        "*formula error > 1 sd*: fits whose parameters the model formula's own error (against the",
        "exact V-cavity model `oren-nayar-exact`, docs/validity.md) moves by more than one posterior",
        "standard deviation, of the fits where gonio checks it.",
        "",
        "## Samples",
        "",
        "s: estimated relative noise. rho, sigma: MCMC median [95 % interval] of the chosen model (sigma",
        f"in deg; - where the model has none); last sigma column: {reference} on every sample. redchi:",
        "reduced chi-square of each candidate's maximum-likelihood fit under the noise model, in the",
        "order " + " / ".join(labels) + ", with its verdict: A adequate, N noise understated, I inadequate.",
        "Flags: chains not converged, R-hat or bulk ESS out of bounds, failures, negative values.",
        "",
        f"| # | name | s | chosen (gonio curet) | verdict | rho | sigma [deg] | sigma, {reference} [deg] "
        "| redchi and verdict per candidate | flags |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [sample_row(sample, candidates) for sample in table]
    lines += ["", "## Failures", ""]
    if summary["failures"] or summary["missing"]:
        lines += [f"* curet-{n:02d} x `{spec}`: {reason or 'no reason recorded'}" for n, spec, reason in summary["failures"]]
        lines += [f"* curet-{n:02d} x `{spec}`: not in the batch" for n, spec in summary["missing"]]
    else:
        lines.append("None: every fit finished.")
    lines += [
        "",
        "## Chart",
        "",
        "![sigma per sample](benchmarks/curet_batch.png)",
        "",
        f"Top: sigma of {reference} per sample, median and 95 % interval, coloured by its verdict; a",
        "filled marker where it is the model gonio curet chooses. Bottom: reduced chi-square of every",
        "candidate per sample (log scale; 1 = as good as the smooth series).",
        "",
        "## Run",
        "",
        f"The batch that fitted the table: {run['fitted']} fits, {run['wall_seconds']:.0f} s wall time on "
        f"{run['workers']} joblib workers, finished {run['finished_utc']}; 1-minute load average "
        f"{load['mean']:.2f} (mean of {load['n']} samples) and {load['max']:.2f} (max) on {run['cpu_count']} cores.",
    ]
    workers = context.get("workers")
    if workers:
        one, two = workers["runs"]["1"], workers["runs"]["2"]
        lines += [
            "",
            f"1 against 2 workers, on samples {workers['samples'][0]}-{workers['samples'][-1]} ({workers['tasks']} fits, "
            f"each run in a fresh folder): {one['wall_seconds']:.1f} s with 1 worker (load {one['load_average_1min']['mean']:.2f}), "
            f"{two['wall_seconds']:.1f} s with 2 (load {two['load_average_1min']['mean']:.2f}): "
            f"**{workers['speed_up']:.2f}x**; the numbers "
            + ("equal those of the main batch (same seeds)." if workers["same_numbers_as_main_batch"] else
               "**differ** from those of the main batch."),
        ]
    lines += ["", "Machine, settings and every fit's numbers: docs/benchmarks/curet_batch.json.", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------- chart and JSON
VERDICT_COLOURS = {"adequate": "C2", "noise understated": "C1", "inadequate": "C3"}


def chart(table: Sequence[Mapping[str, Any]], candidates: Sequence[str], credit: str, path: Path = CHART) -> Path:
    """sigma of the reference model per sample (coloured by verdict) and every candidate's reduced chi-square."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(11.0, 6.6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    for sample in table:
        fit = sample["fits"].get(REFERENCE_MODEL) or {}
        stats = fit.get("parameters", {}).get("sigma")
        if fit.get("status") != "ok" or not stats:
            continue
        colour = VERDICT_COLOURS.get(fit.get("verdict"), "0.5")
        x, m = sample["number"], stats["median"]
        top.errorbar([x], [m], yerr=[[m - stats["p2_5"]], [stats["p97_5"] - m]], fmt="o", ms=5, color=colour,
                     mfc=colour if sample["chosen"] == REFERENCE_MODEL else "white", capsize=2, lw=1)
    top.set_ylabel(f"sigma of {comparison_label(REFERENCE_MODEL)} [deg]")
    top.set_ylim(bottom=0)
    top.grid(alpha=0.3)
    handles = [Line2D([], [], marker="o", ls="", color=c, label=v) for v, c in VERDICT_COLOURS.items()]
    handles += [Line2D([], [], marker="o", ls="", color="0.3", mfc="0.3", label="chosen by gonio curet"),
                Line2D([], [], marker="o", ls="", color="0.3", mfc="white", label="another model chosen")]
    top.legend(handles=handles, fontsize=7, ncols=5, loc="upper left")
    top.set_title("Every CUReT sample: posterior median and 95 % interval (noise model + fitted jitter)\n" + credit,
                  fontsize=8)
    markers = "sD^o"
    for k, spec in enumerate(candidates):
        xs, ys = [], []
        for sample in table:
            fit = sample["fits"].get(spec) or {}
            if fit.get("status") == "ok" and fit.get("redchi") is not None and math.isfinite(fit["redchi"]):
                xs.append(sample["number"] + (k - 1.5) * 0.15)
                ys.append(fit["redchi"])
        bottom.plot(xs, ys, markers[k % len(markers)], ms=3.5, color=f"C{[7, 1, 0, 4][k % 4]}", alpha=0.8,
                    mfc="none", label=comparison_label(spec))
    bottom.axhline(1.0, color="k", lw=0.8, ls="--")
    bottom.set_yscale("log")
    bottom.set_ylabel("reduced chi-square")
    bottom.set_xlabel("CUReT sample number")
    bottom.grid(alpha=0.3)
    bottom.legend(fontsize=7, ncols=len(candidates), loc="upper left")
    bottom.set_xticks(range(1, len(table) + 1, 2) if len(table) > 30 else [s["number"] for s in table])
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    return path


def _jsonable(value: Any) -> Any:
    """NaN and infinity as null, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


# ---------------------------------------------------------------------- main
def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=WORKERS, help=f"joblib workers (default {WORKERS})")
    parser.add_argument("--compare-workers", type=int, default=10, metavar="N",
                        help="also time samples 1..N with 1 and with 2 workers, once (0: no; default 10)")
    args = parser.parse_args(argv)

    from gonio.cli.curet import CREDIT, DEFAULT_CANDIDATES

    batch = run_batch(args.workers)
    runs = append_run(batch["record"])
    rows = batch["rows"]
    numbers = sorted({int(row["input"].split("-")[1]) for row in rows})
    workers_file = BUILD.parent / "curet-batch-workers.json"
    workers = json.loads(workers_file.read_text()) if workers_file.is_file() else None
    if args.compare_workers and workers is None:
        workers = worker_comparison(numbers[:args.compare_workers], {row["task_id"]: row for row in rows})
        workers_file.write_text(json.dumps(_jsonable(workers), indent=1) + "\n")
    compared = comparisons(numbers, args.workers)
    table = sample_table(rows, compared)
    candidates = list(DEFAULT_CANDIDATES)
    summary = summarise(table, candidates)
    fitting_run = max((r for r in runs if r["out"] == batch["record"]["out"]), key=lambda r: r["fitted"])
    settings = batch_settings()
    context = {"candidates": candidates, "summary": summary, "mcmc": mcmc_design(), "credit": CREDIT,
               "run": fitting_run, "workers": workers, "rhat_limit": settings.rhat_limit}
    PAGE.write_text(markdown(table, context))
    chart_path = chart(table, candidates, CREDIT)
    json_path = write_json("curet_batch", _jsonable({
        "benchmark": "curet_batch",
        "command": "python benchmarks/curet_batch.py",
        "equivalent_cli": COMMAND,
        "machine": machine(),
        "credit": CREDIT,
        "mcmc": mcmc_design(),
        "seed": SEED,
        "candidates": candidates,
        "settings": settings.to_dict(),
        "noise_model": "gonio curet (kvd): relative s from the scatter about a KvD order-6 series",
        "chosen_by": "gonio.fitting.compare_models(dataset, candidates, jitter='absolute'), as gonio curet fit",
        "runs": runs,
        "fitting_run": fitting_run,
        "load_average_1min": fitting_run["load_average_1min"],
        "workers_comparison": workers,
        "summary": summary,
        "samples": table,
    }))
    print(f"wrote {PAGE}, {json_path}, {chart_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

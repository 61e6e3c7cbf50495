"""Are gonio's posterior intervals calibrated on emulated rig data, and does model selection
pick the true model?

Two studies on the emulated rig (``gonio.cli.run.emulated_rig``, default noise: CCD shot,
read and dark noise with PRNU, lamp flicker and drift on, lamp monitor on, stage readback
and apertures as built), each run measured with a shortened protocol, reduced with
``gonio.reduction.reduce_recording`` and fitted with the dataset and calibration prior of
``Reduced.fit_inputs()`` (relative radiance, a Gaussian prior on ``scale``):

1. **Coverage and simulation-based calibration** (Talts et al. 2018, arXiv:1804.06788).
   For every seed the truth (rho, sigma) is drawn from the prior ``rho ~ U(0.5, 0.95)``,
   ``sigma ~ U(5, 45) deg``; the sample is that model on the emulated rig; the fit is
   ``gonio.fitting.fit`` with exactly that prior for rho and sigma (plus the calibration
   prior on ``scale``) and gonio's default MCMC (emcee's differential-evolution move, 32
   walkers, chain 50 tau long with a stable tau and R-hat < 1.01; :func:`mcmc_design`). Recorded per seed and parameter: whether the 68 %
   (p16-p84) and 95 % (p2.5-p97.5) posterior intervals contain the truth; the SBC rank
   of the truth among ``SBC_DRAWS`` posterior draws picked at random (without
   replacement) from ``result.samples()``; the least-squares intervals (value +- 1 and
   1.96 stderr); the z-scores (median - truth) / posterior sd and (value - truth) /
   stderr; reduced chi-square, the adequacy verdict, convergence and wall times. Arms:

   - ``closed-form``: sample ``oren-nayar`` (ir_weight = 1), fit ``oren-nayar`` with
     ``ir_weight`` fixed at 1. The model is exact: what the fit does not contain is the
     emulator's noise processes.
   - ``tabulated``: sample ``oren-nayar-exact``, fit ``oren-nayar-tabulated`` (the
     interpolated table of the exact model): what the table's interpolation error does
     to coverage at this noise level.

   Targets: 95 % intervals cover 93-97 % and 68 % intervals cover 63-73 % of seeds, for
   rho and sigma. Coverage is reported with Wilson 95 % intervals, ranks as histograms
   with the binomial 99 % band of a uniform histogram per bin.

2. **Model selection.** For each true sample (``SELECTION_TRUTHS``) and seed,
   ``gonio.fitting.compare_models`` with ``CANDIDATES`` and the calibration prior (least
   squares, goodness-of-fit test, Laplace evidence; no MCMC): the chosen candidate,
   whether it is adequate, whether the comparison could use the evidence or fell back to
   BIC, and every candidate's chi-square, p-value, evidence and BIC. Reported: the
   confusion table truth x chosen candidate, the family accuracy (the chosen candidate is
   adequate and of the generating family), the fraction of seeds with no adequate
   candidate, and the smallest roughness of ``oren-nayar-exact`` that is told from
   Lambert (the choice is not ``lambert``) in >= 95 % of seeds.

**Realism.** ``--realism lab`` (what the commands default to) measures on a real lab's rig
(misalignment, stray light, non-linearity, beam profile, the sample's texture and wedge,
a monitor that does not see the sample's beam exactly; docs/emulator.md), and every fit
and comparison then does what a user must there: the calibration per incidence and the
rig's errors as parameters (``alignment="all"``, ``stray_light=True``; docs/fitting.md);
the selection protocol then reads the reference standard at theta_i = 75 deg too
(:func:`selection_protocol`), since each lamp polar angle needs its own reading.
``--realism ideal`` (the default of this script, the study's first figures) is the
idealised rig. Outputs of the lab study are named with ``_lab``. ``--texture-slope`` (with
``--realism lab``) fits the sample's mesoscale slope too (``texture_slope``, the lab
samples' texture; outputs named with ``_texture``), and ``--truths`` restricts the
model-choice study to some true samples (``--truths on+ts,lambert``).

Writes docs/benchmarks/calibration.json and calibration_coverage.png,
calibration_ranks.png, calibration_zscores.png, calibration_confusion.png (``--quick``:
the same names with ``_quick``). Exits 0 whether or not the targets are met.

Run: ``python benchmarks/calibration.py`` (35-60 minutes on two cores);
``python benchmarks/calibration.py --quick`` for a smoke run of a few minutes.
"""
from __future__ import annotations

import os

# One thread per worker process: the benchmark runs its own worker pool.
for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import json
import math
import multiprocessing
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import OUT, machine, mcmc_design, wilson, write_json  # noqa: E402

# --------------------------------------------------------------------------- design
#: Albedo of the emulated reference standard (the certificate of the Fig 16 protocol).
REFERENCE_REFLECTANCE = 0.99
#: Prior of the coverage study, from which each seed's truth is drawn [-], [deg].
PRIOR = {"rho": (0.5, 0.95), "sigma": (5.0, 45.0)}
#: Posterior draws the truth is ranked among (SBC): ranks 0..SBC_DRAWS.
SBC_DRAWS = 99
#: Bins of the rank histograms.
RANK_BINS = 10
#: Probability of the per-bin band drawn on the rank histograms.
RANK_BAND = 0.99
#: Coverage targets by nominal level.
COVERAGE_TARGETS = {"68": (0.63, 0.73), "95": (0.93, 0.97)}
#: Nominal probability of each interval.
NOMINAL = {"68": 0.6827, "95": 0.95}
#: Fraction of seeds a target of model selection asks for.
SELECTION_TARGET = 0.95
#: Seed offset of the truth draws (separate stream from the emulator's seed).
TRUTH_STREAM = 180406788

#: Part 1 protocol: the shipped Fig 16 sweep (theta_i = 30, 45, 60 deg in the plane of
#: incidence, with the reference standard) with the camera every 10 deg instead of 5.
FIG16 = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"


def coverage_protocol_text() -> str:
    """Protocol of the coverage study: Fig 16 with ``step = 10`` (as tests/test_demo.py)."""
    return FIG16.read_text().replace("step = 5", "step = 10")


#: Part 2 protocol: the Fig 16 in-plane sweeps and the two off-plane sweeps of Fig 19
#: (protocols/oren-nayar-fig19-off-plane.toml), the camera every 10 deg, one recording
#: with the Fig 16 reference standard.
SELECTION_PROTOCOL = """\
[protocol]
name = "calibration-selection"
description = "Fig 16 in-plane and Fig 19 off-plane sweeps, camera every 10 deg"

[sample]
label = "emulated sample"

[exposure]
mode = "auto"
time = 0.02

[darks]
at_start = true
every = 20

[[block]]
name = "in plane (Fig 16)"
theta_i = [30, 45, 60]
phi_i = 0
view = { start = -80, stop = 80, step = 10 }

[[block]]
name = "theta_i = 60, phi_r - phi_i = 45 (Fig 19a)"
theta_i = 60
phi_i = -45
view = { start = 0, stop = 80, step = 10 }

[[block]]
name = "theta_i = 75, phi_r - phi_i = 60 (Fig 19b)"
theta_i = 75
phi_i = -60
view = { start = 0, stop = 80, step = 10 }

[reference]
label = "diffuse reflectance standard, 99 %"
reflectance = 0.99
geometries = [[30, 0, -10], [45, 0, -10], [60, 0, -10]]
"""




def selection_protocol() -> str:
    """:data:`SELECTION_PROTOCOL`, with the standard read at theta_i = 75 deg too when
    every incidence is calibrated by its own reading (``--realism lab``)."""
    if calibration() == "common":
        return SELECTION_PROTOCOL
    return SELECTION_PROTOCOL.replace("[60, 0, -10]]", "[60, 0, -10], [75, 0, -10]]")


@dataclass(frozen=True)
class CoverageArm:
    """One arm of the coverage study: the emulated sample model and the fitted model."""

    key: str
    label: str
    sample_model: str
    sample_fixed: Mapping[str, float]
    fit_model: str
    fit_fixed: Mapping[str, float]
    seed_offset: int

    def describe(self) -> dict[str, Any]:
        return {"key": self.key, "label": self.label, "sample_model": self.sample_model,
                "sample_fixed": dict(self.sample_fixed), "fit_model": self.fit_model,
                "fit_fixed": dict(self.fit_fixed), "seed_offset": self.seed_offset}


COVERAGE_ARMS = (
    CoverageArm("closed-form", "sample oren-nayar, fit oren-nayar (ir_weight = 1)", "oren-nayar",
                {"ir_weight": 1.0}, "oren-nayar", {"ir_weight": 1.0}, 0),
    CoverageArm("tabulated", "sample oren-nayar-exact, fit oren-nayar-tabulated", "oren-nayar-exact", {},
                "oren-nayar-tabulated", {}, 10000),
)

#: Candidate models of the selection study, (name, fixed). In the combined model ``kd`` is
#: fixed at 1 (it multiplies rho except in the interreflection term, so rho and kd are
#: degenerate when sigma is small) and ``n`` at 1.5 (no effect with fresnel = "unity").
CANDIDATES: tuple[tuple[str, dict[str, float]], ...] = (
    ("lambert", {}),
    ("oren-nayar-qualitative", {}),
    ("oren-nayar", {"ir_weight": 1.0}),
    ("oren-nayar-tabulated", {}),
    ("pitted", {}),
    ("oren-nayar+torrance-sparrow", {"kd": 1.0, "n": 1.5}),
)
#: Model family of every candidate model name.
FAMILY = {"lambert": "lambert", "oren-nayar-qualitative": "oren-nayar", "oren-nayar": "oren-nayar",
          "oren-nayar-tabulated": "oren-nayar", "oren-nayar-exact": "oren-nayar", "pitted": "pitted",
          "oren-nayar+torrance-sparrow": "oren-nayar+torrance-sparrow"}


@dataclass(frozen=True)
class SelectionTruth:
    """A true sample of the selection study."""

    key: str
    model: str
    params: Mapping[str, float]

    @property
    def spec(self) -> str:
        return self.model + ":" + ",".join(f"{k}={v:g}" for k, v in self.params.items())

    @property
    def family(self) -> str:
        return FAMILY[self.model]


#: The comparison's extra-noise mode: "auto", the default of ``gonio fit`` and ``gonio demo``
#: (the three verdicts: an extra noise only where the lack-of-fit test says the stated noise
#: is short, docs/fitting.md "Goodness of fit: three verdicts").
SELECTION_JITTER = "auto"

SELECTION_TRUTHS = (
    SelectionTruth("lambert", "lambert", {"rho": 0.8}),
    *(SelectionTruth(f"exact-sigma-{s:g}", "oren-nayar-exact", {"rho": 0.9, "sigma": s})
      for s in (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0)),
    SelectionTruth("pitted", "pitted", {"rho": 0.8, "psi": 60.0, "coverage": 0.4}),
    SelectionTruth("on+ts", "oren-nayar+torrance-sparrow",
                   {"rho": 0.8, "sigma": 20.0, "kd": 1.0, "ks": 0.05, "sigma_s": 10.0, "n": 1.5}),
)


# --------------------------------------------------------------------------- one run
def candidate_label(name: str, fixed: Mapping[str, float]) -> str:
    from gonio.fitting.selection import candidate_label as label

    return label(name, fixed)


def warm_up() -> None:
    """Compile (or load from numba's cache) every model the emulator evaluates.

    The emulator evaluates the sample while the camera exposes; a first-use compilation
    there takes longer than the camera driver's reply timeout (3 s) and stops the run.
    """
    import gonio

    geometry = (45.0, 0.0, np.array([20.0, 40.0]), np.array([180.0, 0.0]))
    for truth in SELECTION_TRUTHS:
        gonio.brdf(truth.model, *geometry, **truth.params)
        gonio.models.get(truth.model).at(*geometry)(**truth.params)
    gonio.brdf("oren-nayar-tabulated", *geometry, rho=0.9, sigma=20.0)
    gonio.models.get("oren-nayar-tabulated").at(*geometry)(rho=0.9, sigma=20.0)


#: The realism of the runs (``--realism``) and what fits do about it (set by :func:`main`):
#: ``texture_slope`` (``--texture-slope``) adds the sample's mesoscale slope to the rig's errors.
REALISM = {"spec": "ideal", "texture_slope": False}


def rig_errors() -> dict[str, Any]:
    """What every fit and comparison models of the rig: nothing on the ideal rig; the
    alignment and the stray light on a rig with systematic errors."""
    if REALISM["spec"] == "ideal":
        return {}
    return {"alignment": "all,texture_slope" if REALISM["texture_slope"] else "all", "stray_light": True}


def calibration() -> str:
    """The dataset's calibration: one E_0 on the ideal rig, per incidence on a lab's."""
    return "common" if REALISM["spec"] == "ideal" else "per-incidence"


def measure(text: str, sample: str, seed: int, folder: Path) -> float:
    """Run a protocol on the emulated rig (the study's realism) into ``folder``; wall time [s]."""
    from gonio import acquisition, protocols
    from gonio.cli.run import emulated_rig

    protocol = protocols.loads(text)
    start = time.perf_counter()
    # the rig's name travels in a URL query (gonio-sim://...?rig=NAME), where "+" would read as a space
    name = "".join(c if c.isalnum() or c == "-" else "-" for c in f"calibration-{os.getpid()}-{seed}-{folder.name}")
    with emulated_rig(sample, seed, name=name, realism=REALISM["spec"]) as (rig, emulator, change_sample, metadata):
        acquisition.run_protocol(protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                                 change_sample=lambda which, **how: change_sample(which, REFERENCE_REFLECTANCE, **how))
    return time.perf_counter() - start


def draw_truth(arm: CoverageArm, seed: int) -> dict[str, float]:
    """The seed's truth, drawn from :data:`PRIOR` (rounded to the 10 digits the spec carries)."""
    rng = np.random.default_rng([TRUTH_STREAM, arm.seed_offset + seed])
    return {name: float(f"{rng.uniform(lo, hi):.10g}") for name, (lo, hi) in PRIOR.items()}


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def coverage_run(arm: CoverageArm, seed: int, scratch: Path) -> dict[str, Any]:
    """Measure, reduce and fit one seed of a coverage arm (module docstring, study 1)."""
    from gonio.fitting import ConvergenceWarning, fit
    from gonio.fitting.priors import Uniform
    from gonio.reduction import reduce_recording

    truth = draw_truth(arm, seed)
    sample = arm.sample_model + ":" + ",".join(f"{k}={v:.10g}" for k, v in {**truth, **arm.sample_fixed}.items())
    folder = scratch / f"{arm.key}-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    start = time.perf_counter()
    measure_wall = measure(coverage_protocol_text(), sample, arm.seed_offset + seed, folder)
    reduced = reduce_recording(folder)
    dataset, priors = reduced.fit_inputs(calibration())
    shutil.rmtree(folder, ignore_errors=True)
    fit_priors = {**priors, **{name: Uniform(lo, hi) for name, (lo, hi) in PRIOR.items()}}
    fit_start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        result = fit(dataset, arm.fit_model, fixed=dict(arm.fit_fixed), priors=fit_priors, seed=seed, **rig_errors())
    fit_wall = time.perf_counter() - fit_start
    samples = result.samples()
    rng = np.random.default_rng([TRUTH_STREAM, 7, arm.seed_offset + seed])
    pick = rng.choice(len(samples), size=min(SBC_DRAWS, len(samples)), replace=False)
    ls = result.least_squares
    post = result.posterior
    mcmc = result.mcmc
    record: dict[str, Any] = {
        "arm": arm.key, "seed": seed, "emulator_seed": arm.seed_offset + seed, "sample": sample, "truth": truth,
        "n_data": int(len(dataset.value)), "redchi": ls.redchi, "dof": ls.dof, "chi2_p": result.adequacy.chi2_p,
        "ppc_p": result.adequacy.ppc_p, "adequate": bool(result.adequacy.adequate),
        "converged": bool(result.converged), "convergence_warnings": len(caught),
        "n_steps": mcmc.n_steps, "tau_max": float(np.max(mcmc.tau)), "ess_min": float(np.min(mcmc.ess)),
        "r_hat_max": float(max(d["r_hat"] for d in mcmc.diagnostics.values())),
        "n_samples": int(len(samples)), "acceptance": float(np.mean(mcmc.acceptance_fraction)),
        "scale": {"median": post["median"]["scale"], "prior_mean": priors["scale"].mean,
                  "prior_sd": priors["scale"].sd, "ls": ls.values["scale"], "ls_stderr": ls.stderr["scale"]},
        "measure_wall_s": measure_wall, "fit_wall_s": fit_wall, "wall_s": time.perf_counter() - start,
        "params": {},
    }
    for name, value in truth.items():
        column = samples[:, list(result.free).index(name)]
        sd = float(np.std(column, ddof=1))
        median = post["median"][name]
        ls_value, ls_error = ls.values[name], ls.stderr[name]
        record["params"][name] = {
            "median": median, "p2_5": post["p2_5"][name], "p16": post["p16"][name], "p84": post["p84"][name],
            "p97_5": post["p97_5"][name], "sd": sd,
            "in68": bool(post["p16"][name] <= value <= post["p84"][name]),
            "in95": bool(post["p2_5"][name] <= value <= post["p97_5"][name]),
            "rank": int(np.sum(column[pick] < value)),
            "z": (median - value) / sd,
            "ls_value": ls_value, "ls_stderr": ls_error,
            "ls_in68": bool(abs(ls_value - value) <= ls_error),
            "ls_in95": bool(abs(ls_value - value) <= 1.96 * ls_error),
            "ls_z": (ls_value - value) / ls_error,
        }
    return record


def selection_run(truth: SelectionTruth, seed: int, scratch: Path) -> dict[str, Any]:
    """Measure, reduce and compare the candidates on one seed of a true sample (study 2)."""
    from gonio.fitting import compare_models
    from gonio.reduction import reduce_recording

    folder = scratch / f"{truth.key}-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    start = time.perf_counter()
    measure_wall = measure(selection_protocol(), truth.spec, seed, folder)
    dataset, priors = reduce_recording(folder).fit_inputs(calibration())
    shutil.rmtree(folder, ignore_errors=True)
    compare_start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        comparison = compare_models(dataset, CANDIDATES, priors=priors, jitter=SELECTION_JITTER, **rig_errors())
    rows = [{"label": r["label"], "model": r["model"], "k": r["k"], "chi2": r["chi2"], "redchi": r["redchi"],
             "chi2_p": r["chi2_p"], "adequate": bool(r["adequate"]), "log_evidence": r["log_evidence"],
             "bic": r["bic"], "verdict": r.get("verdict"), "lack_of_fit_p": r.get("lack_of_fit_p"),
             "evidence_method": r.get("evidence_method")} for r in comparison.rows]
    chosen = comparison.row(comparison.chosen)
    return {
        "truth": truth.key, "seed": seed, "n_data": int(len(dataset.value)), "chosen": comparison.chosen,
        "chosen_model": chosen["model"], "chosen_adequate": bool(comparison.chosen_adequate),
        "chosen_verdict": comparison.chosen_verdict, "jitter": comparison.jitter,
        "used_evidence": all(math.isfinite(r["log_evidence"]) for r in comparison.rows
                             if r["evidence_method"] != "not needed"),  # failing rows need none
        "reason": comparison.reason, "chosen_values": dict(chosen["values"]), "rows": rows,
        "measure_wall_s": measure_wall, "compare_wall_s": time.perf_counter() - compare_start,
        "wall_s": time.perf_counter() - start,
    }


# --------------------------------------------------------------------------- the pool
_SCRATCH: Path | None = None


def _init_worker(scratch: str) -> None:
    global _SCRATCH
    _SCRATCH = Path(scratch)
    warnings.simplefilter("ignore", RuntimeWarning)
    warm_up()


def _run_task(task: tuple[str, str, int]) -> dict[str, Any]:
    """Run one task, retried once on an instrument failure; a failure is recorded, not raised."""
    kind, key, seed = task
    errors = []
    for _ in range(2):
        try:
            if kind == "coverage":
                arm = {a.key: a for a in COVERAGE_ARMS}[key]
                record = coverage_run(arm, seed, _SCRATCH)
            else:
                truth = {t.key: t for t in SELECTION_TRUTHS}[key]
                record = selection_run(truth, seed, _SCRATCH)
            record["attempts"] = len(errors) + 1
            record["errors"] = errors
            return {"kind": kind, "key": key, "seed": seed, "failed": False, "record": record}
        except Exception as error:  # noqa: BLE001 - recorded and reported
            errors.append(f"{type(error).__name__}: {error}\n{traceback.format_exc(limit=3)}")
    return {"kind": kind, "key": key, "seed": seed, "failed": True, "errors": errors}


def run_tasks(tasks: Sequence[tuple[str, str, int]], workers: int, records_path: Path) -> list[dict[str, Any]]:
    """Run tasks in a pool, appending each outcome to ``records_path`` (JSON lines) as it
    arrives; tasks already in that file are not run again (a resumed benchmark)."""
    done: dict[tuple[str, str, int], dict[str, Any]] = {}
    if records_path.exists():
        for line in records_path.read_text().splitlines():
            if line.strip():
                outcome = json.loads(line)
                if outcome.get("kind") != "session" and not outcome["failed"]:
                    done[(outcome["kind"], outcome["key"], outcome["seed"])] = outcome
    todo = [t for t in tasks if t not in done]
    print(f"{len(tasks)} runs, {len(tasks) - len(todo)} already in {records_path}, {len(todo)} to do, "
          f"{workers} worker(s)", flush=True)
    start = time.perf_counter()
    scratch = Path(tempfile.mkdtemp(prefix="gonio-calibration-"))
    outcomes = [done[t] for t in tasks if t in done]
    try:
        with multiprocessing.get_context("fork").Pool(workers, _init_worker, (str(scratch),)) as pool, \
                records_path.open("a") as sink:
            for k, outcome in enumerate(pool.imap_unordered(_run_task, todo), start=1):
                sink.write(json.dumps({**outcome, "commit": git_state()["commit"]}) + "\n")
                sink.flush()
                outcomes.append({**outcome, "session": "this"})
                elapsed = time.perf_counter() - start
                eta = elapsed / k * (len(todo) - k)
                status = "FAILED" if outcome["failed"] else f"{outcome['record']['wall_s']:.1f} s"
                extra = ""
                if not outcome["failed"] and outcome["kind"] == "coverage":
                    r = outcome["record"]
                    extra = " ".join(f"{n} z={p['z']:+.2f}" for n, p in r["params"].items())
                    extra += f" redchi={r['redchi']:.2f}{'' if r['converged'] else ' NOT CONVERGED'}"
                elif not outcome["failed"]:
                    r = outcome["record"]
                    extra = f"chosen {r['chosen']}{'' if r['chosen_adequate'] else ' (none adequate)'}"
                print(f"[{k}/{len(todo)}] {outcome['kind']} {outcome['key']} seed {outcome['seed']}: {status} "
                      f"{extra}  (elapsed {elapsed / 60:.1f} min, eta {eta / 60:.1f} min)", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return outcomes


# --------------------------------------------------------------------------- statistics

def proportion(flags: Sequence[bool]) -> dict[str, Any]:
    k, n = int(np.sum(flags)), len(flags)
    return {"k": k, "n": n, "fraction": k / n if n else math.nan, "wilson95": wilson(k, n)}


def coverage_verdict(summary: Mapping[str, Any], level: str) -> str:
    """``met`` (point estimate in the band), ``consistent`` (outside it, Wilson interval
    overlapping it) or ``missed`` (Wilson interval entirely outside the band)."""
    lo, hi = COVERAGE_TARGETS[level]
    f, (c_lo, c_hi) = summary["fraction"], summary["wilson95"]
    if lo <= f <= hi:
        return "met"
    return "consistent" if c_hi >= lo and c_lo <= hi else "missed"


def rank_summary(ranks: Sequence[int]) -> dict[str, Any]:
    """Rank histogram, its uniform 99 % band per bin and a chi-square test of uniformity."""
    ranks = np.asarray(ranks, int)
    n = len(ranks)
    edges = np.linspace(0, SBC_DRAWS + 1, RANK_BINS + 1)
    counts = np.histogram(ranks, bins=edges)[0]
    expected = n / RANK_BINS
    tail = (1 - RANK_BAND) / 2
    band = [float(stats.binom.ppf(tail, n, 1 / RANK_BINS)), float(stats.binom.ppf(1 - tail, n, 1 / RANK_BINS))]
    chi2 = stats.chisquare(counts) if n else None
    u = (ranks + 0.5) / (SBC_DRAWS + 1)
    return {"counts": counts.tolist(), "edges": edges.tolist(), "expected": expected, "band99": band,
            "bins_outside_band": int(np.sum((counts < band[0]) | (counts > band[1]))),
            "chi2": float(chi2.statistic) if chi2 else math.nan, "chi2_p": float(chi2.pvalue) if chi2 else math.nan,
            "outer_fraction": float(np.mean((u < 0.05) | (u > 0.95))) if n else math.nan,
            "mean_normalised_rank": float(np.mean(u)) if n else math.nan}


def z_summary(z: Sequence[float]) -> dict[str, float]:
    z = np.asarray(z, float)
    return {"mean": float(np.mean(z)), "sd": float(np.std(z, ddof=1)), "rms": float(np.sqrt(np.mean(z ** 2))),
            "median_abs": float(np.median(np.abs(z))), "max_abs": float(np.max(np.abs(z))),
            "fraction_abs_gt_3": float(np.mean(np.abs(z) > 3))}


def summarise_coverage(records: Sequence[Mapping[str, Any]], arm: CoverageArm) -> dict[str, Any]:
    """Coverage, SBC ranks and z-score diagnostics of one arm."""
    out: dict[str, Any] = {"arm": arm.describe(), "n": len(records)}
    if not records:
        return out
    out["converged"] = proportion([r["converged"] for r in records])
    out["adequate"] = proportion([r["adequate"] for r in records])
    redchi = np.array([r["redchi"] for r in records])
    out["redchi"] = {"median": float(np.median(redchi)), "p5": float(np.percentile(redchi, 5)),
                     "p95": float(np.percentile(redchi, 95)), "dof_median": float(np.median([r["dof"] for r in records]))}
    out["chi2_p_below_0.05"] = proportion([r["chi2_p"] < 0.05 for r in records])
    out["n_data"] = int(np.median([r["n_data"] for r in records]))
    out["wall_s"] = {key: {"median": float(np.median([r[key] for r in records])),
                           "max": float(np.max([r[key] for r in records]))}
                     for key in ("measure_wall_s", "fit_wall_s", "wall_s")}
    out["mcmc"] = {"n_steps_median": float(np.median([r["n_steps"] for r in records])),
                   "tau_max_median": float(np.median([r["tau_max"] for r in records])),
                   "ess_min_median": float(np.median([r["ess_min"] for r in records])),
                   "r_hat_max": float(np.max([r["r_hat_max"] for r in records]))}
    scale_pull = [(r["scale"]["median"] - r["scale"]["prior_mean"]) / r["scale"]["prior_sd"] for r in records]
    out["scale_pull_vs_prior"] = z_summary(scale_pull)
    out["params"] = {}
    for name in PRIOR:
        p = [r["params"][name] for r in records]
        truth = np.array([r["truth"][name] for r in records])
        entry: dict[str, Any] = {}
        for level in ("68", "95"):
            for method, key in (("posterior", f"in{level}"), ("least_squares", f"ls_in{level}")):
                summary = proportion([q[key] for q in p])
                summary["target"] = list(COVERAGE_TARGETS[level])
                summary["verdict"] = coverage_verdict(summary, level)
                summary["binomial_p_vs_nominal"] = float(stats.binomtest(summary["k"], summary["n"],
                                                                          NOMINAL[level]).pvalue)
                entry[f"{method}_{level}"] = summary
        entry["ranks"] = rank_summary([q["rank"] for q in p])
        z = np.array([q["z"] for q in p])
        ls_z = np.array([q["ls_z"] for q in p])
        entry["z_posterior"] = z_summary(z)
        entry["z_least_squares"] = z_summary(ls_z)
        sd = np.array([q["sd"] for q in p])
        ls_err = np.array([q["ls_stderr"] for q in p])
        entry["posterior_sd_over_ls_stderr_median"] = float(np.median(sd / ls_err))
        # dependence of the normalised error on the truth
        entry["z_vs_truth"] = {}
        for other in PRIOR:
            t = np.array([r["truth"][other] for r in records])
            rho_s = stats.spearmanr(t, np.abs(z)) if len(t) > 2 else None
            thirds = np.array_split(np.argsort(t), 3)
            entry["z_vs_truth"][other] = {
                "spearman_abs_z": float(rho_s.statistic) if rho_s else math.nan,
                "spearman_p": float(rho_s.pvalue) if rho_s else math.nan,
                "thirds": [{"range": [float(t[idx].min()), float(t[idx].max())], "n": int(len(idx)),
                            "rms_z": float(np.sqrt(np.mean(z[idx] ** 2))), "mean_z": float(np.mean(z[idx])),
                            "cover95": float(np.mean([p[i]["in95"] for i in idx])),
                            "cover68": float(np.mean([p[i]["in68"] for i in idx]))} for idx in thirds if len(idx)],
            }
        entry["truth_range"] = [float(truth.min()), float(truth.max())]
        out["params"][name] = entry
    joint = [r["params"]["rho"]["in95"] and r["params"]["sigma"]["in95"] for r in records]
    out["both_in95"] = proportion(joint)
    z_rho = np.array([r["params"]["rho"]["z"] for r in records])
    z_sigma = np.array([r["params"]["sigma"]["z"] for r in records])
    out["z_correlation_rho_sigma"] = float(np.corrcoef(z_rho, z_sigma)[0, 1]) if len(records) > 2 else math.nan
    out["targets_met"] = {f"{name} {level} %": out["params"][name][f"posterior_{level}"]["verdict"] == "met"
                          for name in PRIOR for level in ("68", "95")}
    return out


def summarise_selection(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Confusion table, family accuracy, detection of roughness (module docstring, study 2)."""
    labels = [candidate_label(n, f) for n, f in CANDIDATES]
    family_of = {candidate_label(n, f): FAMILY[n] for n, f in CANDIDATES}
    columns = labels + ["none adequate"]
    by_truth: dict[str, Any] = {}
    for truth in SELECTION_TRUTHS:
        rs = [r for r in records if r["truth"] == truth.key]
        if not rs:
            continue
        n = len(rs)
        counts = {c: 0 for c in columns}
        best_when_none = {c: 0 for c in labels}
        for r in rs:
            if r["chosen_adequate"]:
                counts[r["chosen"]] += 1
            else:
                counts["none adequate"] += 1
                best_when_none[r["chosen"]] += 1
        family_ok = [r["chosen_adequate"] and family_of[r["chosen"]] == truth.family for r in rs]
        # roughness detected: the comparison does not call the sample Lambertian (its choice
        # is not lambert, whether or not a candidate passes the goodness-of-fit test)
        non_lambert = [r["chosen"] != "lambert" for r in rs]
        lambert_adequate = [next(x for x in r["rows"] if x["label"] == "lambert")["adequate"] for r in rs]
        # The data can tell the family when every candidate of another family fails the test.
        others_fail = [all(not x["adequate"] for x in r["rows"] if family_of[x["label"]] != truth.family) for r in rs]
        # The evidence rule over the candidates whose Laplace evidence is defined.
        alt = [alternative_choice(r["rows"]) for r in rs]
        alt_counts = {c: 0 for c in columns}
        for a in alt:
            alt_counts[a] += 1
        by_truth[truth.key] = {
            "spec": truth.spec, "family": truth.family, "n": n, "counts": counts,
            "fractions": {c: counts[c] / n for c in columns},
            "best_by_criterion_when_none_adequate": best_when_none,
            "family_accuracy": proportion(family_ok),
            "not_called_lambert": proportion(non_lambert),
            "lambert_adequate": proportion(lambert_adequate),
            "none_adequate": proportion([not r["chosen_adequate"] for r in rs]),
            "data_can_tell": proportion(others_fail),
            "used_evidence": proportion([r["used_evidence"] for r in rs]),
            "chosen_verdicts": {v: sum(str(r.get("chosen_verdict")) == v for r in rs)
                                for v in sorted({str(r.get("chosen_verdict")) for r in rs})},
            "evidence_undefined_by_candidate": {c: int(sum(not _is_finite(next(x for x in r["rows"]
                                                                                if x["label"] == c)["log_evidence"])
                                                           for r in rs)) for c in labels},
            "adequate_by_candidate": {c: int(sum(next(x for x in r["rows"] if x["label"] == c)["adequate"]
                                                 for r in rs)) for c in labels},
            "evidence_rule_over_defined_evidences": alt_counts,
            "wall_s_median": float(np.median([r["wall_s"] for r in rs])),
            "n_data": int(np.median([r["n_data"] for r in rs])),
        }
    # smallest sigma of oren-nayar-exact detected (not called lambert in >= 95 % of seeds),
    # every larger tested sigma detected too
    exact = sorted(((t.params["sigma"], t.key) for t in SELECTION_TRUTHS
                    if t.model == "oren-nayar-exact" and t.key in by_truth), reverse=True)
    smallest = None
    for sigma, key in exact:
        if by_truth[key]["not_called_lambert"]["fraction"] >= SELECTION_TARGET:
            smallest = sigma
        else:
            break
    lambert = by_truth.get("lambert")
    tellable = {k: v for k, v in by_truth.items()
                if k != "lambert" and v["data_can_tell"]["fraction"] >= SELECTION_TARGET}
    targets = {}
    if lambert:
        targets["lambert sample called lambert >= 95 %"] = lambert["counts"]["lambert"] / lambert["n"] >= SELECTION_TARGET
    for k, v in tellable.items():
        targets[f"{k}: generating family >= 95 %"] = v["family_accuracy"]["fraction"] >= SELECTION_TARGET
    all_records = [r for r in records]
    return {"columns": columns, "candidates": [{"label": candidate_label(n, f), "model": n, "fixed": f,
                                                "family": FAMILY[n]} for n, f in CANDIDATES],
            "truths": by_truth, "smallest_detected_sigma": smallest,
            "tested_sigmas": sorted(s for s, _ in exact),
            "truths_where_data_can_tell": sorted(tellable),
            "used_evidence_overall": proportion([r["used_evidence"] for r in all_records]) if all_records else None,
            "none_adequate_overall": proportion([not r["chosen_adequate"] for r in all_records]) if all_records else None,
            "targets_met": targets}


def _is_finite(x: Any) -> bool:
    return x is not None and math.isfinite(float(x))


def alternative_choice(rows: Sequence[Mapping[str, Any]], threshold: float = 1.0) -> str:
    """The choice of the comparison's rule by Laplace evidence alone, over the candidates
    whose evidence is defined (a diagnostic of the BIC fallback; ``none adequate`` when no
    such candidate is adequate)."""
    pool = [r for r in rows if r["adequate"] and _is_finite(r["log_evidence"])]
    if not pool:
        return "none adequate"
    best = max(r["log_evidence"] for r in pool)
    close = [r for r in pool if best - r["log_evidence"] <= threshold]
    return min(close, key=lambda r: (r["k"], -r["log_evidence"]))["label"]


# --------------------------------------------------------------------------- noise-free
#: Roughness grid of the noise-free study of the table [deg], and its albedos.
NOISE_FREE_SIGMAS = tuple(np.arange(5.0, 45.01, 2.5).tolist())
NOISE_FREE_RHOS = (0.7, 0.9)


def _template(text: str, scratch: Path, key: str) -> tuple[Any, dict[str, Any]]:
    """A reduced recording's dataset and priors (geometry, uncertainties, covariance,
    apertures, calibration), from one run of ``text`` on the emulated plaster (seed 0)."""
    from gonio.reduction import reduce_recording

    folder = scratch / f"template-{key}"
    shutil.rmtree(folder, ignore_errors=True)
    measure(text, "oren-nayar:rho=0.9,sigma=30,ir_weight=1", 0, folder)
    dataset, priors = reduce_recording(folder).fit_inputs()
    shutil.rmtree(folder, ignore_errors=True)
    return dataset, priors


def _noise_free(dataset, priors, model: str, params: Mapping[str, float]):
    """``dataset`` with its values replaced by ``model`` (through the apertures, scale = E_0)."""
    import dataclasses

    from gonio.fitting import FitProblem

    values = FitProblem(model, dataset).predict({**params, "scale": priors["scale"].mean})
    return dataclasses.replace(dataset, value=np.asarray(values, float))


def noise_free_study() -> dict[str, Any]:
    """What the table's interpolation error does without noise.

    1. At the coverage protocol's geometries and stated uncertainties, the values of the
       aperture-averaged ``oren-nayar-exact`` (no noise) are fitted by least squares with
       ``oren-nayar-tabulated`` (the coverage study's priors): the shift of rho and sigma
       in units of their standard errors is the bias the table alone causes, and the
       chi-square the misfit left after the parameters absorbed what they can.
    2. At the selection protocol's geometries, the same noise-free values for every
       ``oren-nayar-exact`` truth of the selection study are compared with
       ``compare_models``: the noise-free chi-square of every candidate (on noisy data a
       candidate's chi-square is about its degrees of freedom plus this).
    """
    from gonio.fitting import compare_models, fit
    from gonio.fitting.priors import Uniform

    warm_up()
    start = time.perf_counter()
    scratch = Path(tempfile.mkdtemp(prefix="gonio-calibration-template-"))
    try:
        coverage_ds, coverage_priors = _template(coverage_protocol_text(), scratch, "coverage")
        selection_ds, selection_priors = _template(SELECTION_PROTOCOL, scratch, "selection")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    table = []
    fit_priors = {**coverage_priors, **{name: Uniform(lo, hi) for name, (lo, hi) in PRIOR.items()}}
    for rho in NOISE_FREE_RHOS:
        for sigma in NOISE_FREE_SIGMAS:
            clean = _noise_free(coverage_ds, coverage_priors, "oren-nayar-exact", {"rho": rho, "sigma": sigma})
            ls = fit(clean, "oren-nayar-tabulated", priors=fit_priors, mcmc=False).least_squares
            table.append({"rho": rho, "sigma": sigma, "chi2": ls.chi2, "dof": ls.dof,
                          "rho_shift_over_stderr": (ls.values["rho"] - rho) / ls.stderr["rho"],
                          "sigma_shift_over_stderr": (ls.values["sigma"] - sigma) / ls.stderr["sigma"],
                          "sigma_shift_deg": ls.values["sigma"] - sigma, "sigma_stderr": ls.stderr["sigma"]})
            print(f"noise-free table fit rho {rho:g} sigma {sigma:4.1f}: chi2 {ls.chi2:6.2f}, sigma shift "
                  f"{table[-1]['sigma_shift_over_stderr']:+.2f} stderr, rho shift "
                  f"{table[-1]['rho_shift_over_stderr']:+.2f} stderr", flush=True)
    selection = []
    for truth in SELECTION_TRUTHS:
        if truth.model != "oren-nayar-exact":
            continue
        clean = _noise_free(selection_ds, selection_priors, truth.model, truth.params)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            comparison = compare_models(clean, CANDIDATES, priors=selection_priors)
        chi2 = {r["label"]: r["chi2"] for r in comparison.rows}
        selection.append({"truth": truth.key, "sigma": truth.params["sigma"], "chi2": chi2,
                          "dof": {r["label"]: comparison.fits[r["label"]].dof for r in comparison.rows}})
        print(f"noise-free selection {truth.key}: " + ", ".join(f"{k.split(' (')[0]} {v:.3g}"
                                                               for k, v in chi2.items()), flush=True)
    return {"coverage_protocol_table_fit": table, "selection_protocol_chi2": selection,
            "coverage_n_data": int(coverage_ds.n), "selection_n_data": int(selection_ds.n),
            "median_relative_uncertainty": {
                "coverage": float(np.median(coverage_ds.sigma / np.abs(coverage_ds.value))),
                "selection": float(np.median(selection_ds.sigma / np.abs(selection_ds.value)))},
            "wall_s": time.perf_counter() - start}


# --------------------------------------------------------------------------- charts
def chart_coverage(payload: Mapping[str, Any], path: Path) -> None:
    """Coverage per parameter, level and method with Wilson bars against the target band."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 4.2), layout="constrained")
    axes = fig.subplots(1, 2)
    series = []
    for arm in payload["coverage"]:
        if arm["n"] == 0:
            continue
        series.append((f"{arm['arm']['key']}: posterior (n={arm['n']})", arm, "posterior"))
        if arm["arm"]["key"] == "closed-form":
            series.append((f"{arm['arm']['key']}: least squares +-1, 1.96 stderr", arm, "least_squares"))
    for ax, level in zip(axes, ("68", "95")):
        lo, hi = COVERAGE_TARGETS[level]
        ax.axhspan(lo, hi, color="C2", alpha=0.18, label=f"target {lo:.0%}-{hi:.0%}")
        ax.axhline(NOMINAL[level], color="k", lw=0.8, ls="--", label=f"nominal {NOMINAL[level]:.1%}")
        width = 0.7 / max(len(series), 1)
        for k, (label, arm, method) in enumerate(series):
            for j, name in enumerate(PRIOR):
                s = arm["params"][name][f"{method}_{level}"]
                x = j + (k - (len(series) - 1) / 2) * width
                ax.errorbar([x], [s["fraction"]], yerr=[[s["fraction"] - s["wilson95"][0]],
                                                         [s["wilson95"][1] - s["fraction"]]],
                            fmt="os^"[k % 3], color=f"C{k}", capsize=3, label=label if j == 0 else None)
        ax.set_xticks(range(len(PRIOR)), list(PRIOR))
        ax.set_xlim(-0.6, len(PRIOR) - 0.4)
        ax.set_ylabel("fraction of seeds whose interval holds the truth")
        ax.set_title(f"{level} % intervals (bars: Wilson 95 %)", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    fig.savefig(path, dpi=110)


def chart_ranks(payload: Mapping[str, Any], path: Path) -> None:
    """SBC rank histograms of rho and sigma per arm, with the uniform 99 % band per bin."""
    from matplotlib.figure import Figure

    arms = [a for a in payload["coverage"] if a["n"]]
    fig = Figure(figsize=(10.0, 3.4 * max(len(arms), 1)), layout="constrained")
    axes = np.atleast_2d(fig.subplots(max(len(arms), 1), 2, squeeze=False))
    for row, arm in zip(axes, arms):
        for ax, name in zip(row, PRIOR):
            r = arm["params"][name]["ranks"]
            edges = np.array(r["edges"])
            ax.axhspan(*r["band99"], color="C2", alpha=0.25, zorder=0, label=f"uniform, {RANK_BAND:.0%} band per bin")
            ax.bar(edges[:-1], r["counts"], width=np.diff(edges), align="edge", color="C0", edgecolor="white",
                   alpha=0.85, zorder=2)
            for edge in r["band99"]:
                ax.axhline(edge, color="C2", lw=1.0, ls="--", zorder=3)
            ax.axhline(r["expected"], color="k", lw=0.8, zorder=3)
            ax.set_xlim(0, SBC_DRAWS + 1)
            ax.set_xlabel(f"rank of the truth among {SBC_DRAWS} posterior draws")
            ax.set_ylabel("seeds")
            ax.set_title(f"{arm['arm']['key']}: {name} (n={arm['n']}, chi-square p={r['chi2_p']:.2g})", fontsize=10)
            ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)


def chart_zscores(payload: Mapping[str, Any], records: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Normalised errors (median - truth) / posterior sd against the truth, and their histogram."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.0, 3.8), layout="constrained")
    axes = fig.subplots(1, 3)
    grid = np.linspace(-5, 5, 201)
    for k, arm in enumerate(COVERAGE_ARMS):
        rs = [r for r in records if r["arm"] == arm.key]
        if not rs:
            continue
        for j, name in enumerate(PRIOR):
            z = [r["params"][name]["z"] for r in rs]
            truth_sigma = [r["truth"]["sigma"] for r in rs]
            axes[j].plot(truth_sigma, z, "os"[k], ms=3.5, color=f"C{k}", alpha=0.8,
                         label=f"{arm.key} (rms {np.sqrt(np.mean(np.square(z))):.2f})")
            axes[2].hist(np.clip(z, -5, 5), bins=np.linspace(-5, 5, 26), density=True, histtype="step",
                         color=f"C{2 * k + j}", label=f"{arm.key}: {name}")
    for j, name in enumerate(PRIOR):
        axes[j].axhspan(-1.96, 1.96, color="C2", alpha=0.12)
        axes[j].axhline(0, color="k", lw=0.8)
        axes[j].set_xlabel("true sigma [deg]")
        axes[j].set_ylabel(f"({name} median - truth) / posterior sd")
        axes[j].set_title(f"{name}: normalised error against roughness", fontsize=10)
        axes[j].legend(fontsize=7)
        axes[j].grid(alpha=0.3)
    axes[2].plot(grid, stats.norm.pdf(grid), "k", lw=1, label="N(0, 1)")
    axes[2].set_xlabel("normalised error (clipped at +-5)")
    axes[2].set_title("histogram of normalised errors", fontsize=10)
    axes[2].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def chart_confusion(payload: Mapping[str, Any], path: Path) -> None:
    """The confusion table truth x chosen candidate as a heat map (fractions, counts)."""
    from matplotlib.figure import Figure

    selection = payload["selection"]
    truths = [t for t in SELECTION_TRUTHS if t.key in selection["truths"]]
    columns = selection["columns"]
    matrix = np.array([[selection["truths"][t.key]["fractions"][c] for c in columns] for t in truths])
    fig = Figure(figsize=(11.0, 0.6 * len(truths) + 2.6), layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(matrix, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    for i, t in enumerate(truths):
        for j, c in enumerate(columns):
            count = selection["truths"][t.key]["counts"][c]
            if count:
                ax.text(j, i, f"{matrix[i, j]:.2f}\n({count})", ha="center", va="center", fontsize=7,
                        color="white" if matrix[i, j] > 0.6 else "black")
    ax.set_xticks(range(len(columns)), columns, fontsize=7, rotation=25, ha="right")
    ax.set_yticks(range(len(truths)), [t.model + "\n" + ", ".join(f"{k}={v:g}" for k, v in t.params.items())
                                       + f" (n={selection['truths'][t.key]['n']})" for t in truths], fontsize=7)
    ax.set_xlabel("chosen candidate (compare_models, adequate); last column: no candidate adequate")
    ax.set_title("Model selection on the emulated rig: fraction of seeds", fontsize=10)
    fig.colorbar(image, ax=ax, label="fraction of seeds")
    fig.savefig(path, dpi=110)


# --------------------------------------------------------------------------- output
def _clean(value: Any) -> Any:
    """NaN and inf as null (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.generic):
        return _clean(value.item())
    return value


def _fmt_ci(s: Mapping[str, Any]) -> str:
    return f"{s['fraction']:.3f} [{s['wilson95'][0]:.3f}, {s['wilson95'][1]:.3f}] ({s['k']}/{s['n']})"


def print_tables(payload: Mapping[str, Any]) -> None:
    for arm in payload["coverage"]:
        if not arm["n"]:
            continue
        print(f"\n== coverage, {arm['arm']['label']}: {arm['n']} seeds; converged {_fmt_ci(arm['converged'])}; "
              f"adequate {_fmt_ci(arm['adequate'])}; median redchi {arm['redchi']['median']:.3f}")
        print(f"{'parameter':<8}{'interval':<28}{'coverage [Wilson 95 %]':<36}{'target':<14}verdict")
        for name, entry in arm["params"].items():
            for method in ("posterior", "least_squares"):
                for level in ("68", "95"):
                    s = entry[f"{method}_{level}"]
                    print(f"{name:<8}{method + ' ' + level + ' %':<28}{_fmt_ci(s):<36}"
                          f"{s['target'][0]:.2f}-{s['target'][1]:.2f}    {s['verdict']}")
            r, z = entry["ranks"], entry["z_posterior"]
            print(f"{'':<8}SBC ranks: counts {r['counts']} (99 % band {r['band99'][0]:.0f}-{r['band99'][1]:.0f}), "
                  f"chi-square p = {r['chi2_p']:.3g}, {r['bins_outside_band']} bin(s) outside the band")
            print(f"{'':<8}z posterior: mean {z['mean']:+.2f}, sd {z['sd']:.2f}, rms {z['rms']:.2f}; "
                  f"least squares rms {entry['z_least_squares']['rms']:.2f}; posterior sd / ls stderr "
                  f"{entry['posterior_sd_over_ls_stderr_median']:.2f}")
    selection = payload.get("selection")
    if selection and selection["truths"]:
        columns = selection["columns"]
        short = [c.split(" (")[0].replace("oren-nayar", "on") for c in columns]
        print("\n== model selection: fraction of seeds (truth x chosen)")
        print(f"{'truth':<22}{'n':>4} " + " ".join(f"{s[:12]:>12}" for s in short) + f"{'family':>8}{'BIC':>6}")
        for key, t in selection["truths"].items():
            print(f"{key:<22}{t['n']:>4} " + " ".join(f"{t['fractions'][c]:>12.2f}" for c in columns)
                  + f"{t['family_accuracy']['fraction']:>8.2f}{1 - t['used_evidence']['fraction']:>6.2f}")
        print("\nthe rule by Laplace evidence alone, over the candidates whose evidence is defined:")
        for key, t in selection["truths"].items():
            alt = t["evidence_rule_over_defined_evidences"]
            print(f"{key:<22}{t['n']:>4} " + " ".join(f"{alt[c] / t['n']:>12.2f}" for c in columns))
        print(f"smallest detected sigma of oren-nayar-exact: {selection['smallest_detected_sigma']} deg "
              f"(tested {selection['tested_sigmas']})")
    print()
    for name, met in payload["targets_met"].items():
        print(f"target {name}: {'met' if met else 'MISSED'}")
    print(f"wall time {payload['wall_s'] / 60:.1f} min over {len(payload['sessions'])} invocation(s)")


def draw_charts(payload: Mapping[str, Any], suffix: str) -> None:
    """Write the four charts of a payload into docs/benchmarks/ (the confusion chart alone
    without coverage runs)."""
    if any(arm["n"] for arm in payload["coverage"]):
        chart_coverage(payload, OUT / f"calibration_coverage{suffix}.png")
        chart_ranks(payload, OUT / f"calibration_ranks{suffix}.png")
        chart_zscores(payload, payload["coverage_records"], OUT / f"calibration_zscores{suffix}.png")
    chart_confusion(payload, OUT / f"calibration_confusion{suffix}.png")


def git_state() -> dict[str, Any]:
    """The commit and whether gonio/ or drivers/ differ from it (what was measured)."""
    def run(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return ""
    return {"commit": run("rev-parse", "HEAD") or None,
            "library_modified": bool(run("status", "--porcelain", "--", "gonio", "drivers"))}


def _chosen_truths(parser: argparse.ArgumentParser, keys: str | None) -> tuple[SelectionTruth, ...]:
    """The true samples ``--truths`` names (all by default); an unknown key is a usage error."""
    if keys is None:
        return SELECTION_TRUTHS
    known = {t.key: t for t in SELECTION_TRUTHS}
    wanted = [k.strip() for k in keys.split(",") if k.strip()]
    unknown = [k for k in wanted if k not in known]
    if unknown or not wanted:
        parser.error(f"--truths: unknown key(s) {', '.join(unknown) or '(none given)'}; known: {', '.join(known)}")
    return tuple(known[k] for k in wanted)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a smoke run: few seeds, outputs named *_quick")
    parser.add_argument("--seeds", type=int, default=None, help="seeds of the closed-form coverage arm (default 160)")
    parser.add_argument("--tabulated-seeds", type=int, default=None,
                        help="seeds of the exact-sample / tabulated-fit arm (default 30; 0 skips it)")
    parser.add_argument("--selection-seeds", type=int, default=None, help="seeds per true sample (default 20)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--realism", choices=("ideal", "lab"), default="ideal",
                        help="the emulated rig: 'ideal' (the study's first figures) or 'lab' (the commands' default: "
                             "fits model the rig's errors); outputs of 'lab' are named *_lab")
    parser.add_argument("--records", type=Path, default=None,
                        help="JSON-lines file of finished runs (appended; runs already in it are not repeated); "
                             "default a file in the temporary directory, removed after a complete run")
    parser.add_argument("--selection-only", action="store_true",
                        help="only the model-choice study (no coverage arms); outputs named *_selection")
    parser.add_argument("--texture-slope", action="store_true",
                        help="with --realism lab: fits and comparisons also carry the sample's mesoscale slope "
                             "(texture_slope, docs/fitting.md); outputs named *_texture")
    parser.add_argument("--truths", default=None,
                        help="comma-separated keys of the true samples of the model-choice study (default all: "
                             + ", ".join(t.key for t in SELECTION_TRUTHS) + ")")
    parser.add_argument("--charts-only", action="store_true",
                        help="redraw the charts from the JSON a previous run wrote; run nothing")
    args = parser.parse_args(argv)
    quick = args.quick
    if args.texture_slope and args.realism != "lab":
        parser.error("--texture-slope needs --realism lab (the ideal rig's samples have no texture)")
    truths = _chosen_truths(parser, args.truths)
    REALISM.update(spec=args.realism, texture_slope=args.texture_slope)
    suffix = (("_lab" if args.realism == "lab" else "") + ("_texture" if args.texture_slope else "")
              + ("_quick" if quick else "") + ("_selection" if args.selection_only else ""))
    if args.selection_only:
        args.seeds, args.tabulated_seeds = 0, 0
    if args.charts_only:
        payload = json.loads((OUT / f"calibration{suffix}.json").read_text())
        draw_charts(payload, suffix)
        print_tables(payload)
        return 0
    n_cov = args.seeds if args.seeds is not None else (4 if quick else 160)
    n_tab = args.tabulated_seeds if args.tabulated_seeds is not None else (2 if quick else 30)
    n_sel = args.selection_seeds if args.selection_seeds is not None else (2 if quick else 20)
    records_path = args.records or Path(tempfile.gettempdir()) / f"gonio-calibration{suffix}-records.jsonl"
    start = time.perf_counter()
    # longest runs first, so that the pool's two workers finish together
    tasks = [("coverage", "tabulated", s) for s in range(1, n_tab + 1)]
    tasks += [("coverage", "closed-form", s) for s in range(1, n_cov + 1)]
    tasks += [("selection", t.key, s) for s in range(1, n_sel + 1) for t in truths]
    outcomes = run_tasks(tasks, args.workers, records_path)
    noise_free = noise_free_study() if not quick and args.realism == "ideal" else None
    session = {"kind": "session", "wall_s": time.perf_counter() - start, "tasks": len(tasks),
               "ran": sum(1 for o in outcomes if o.get("session") == "this"), "git": git_state(),
               "finished": time.strftime("%Y-%m-%dT%H:%M:%S")}
    with records_path.open("a") as sink:
        sink.write(json.dumps(session) + "\n")
    sessions = [json.loads(line) for line in records_path.read_text().splitlines()
                if line.strip() and json.loads(line).get("kind") == "session"]
    failures = [{"kind": o["kind"], "key": o["key"], "seed": o["seed"], "errors": o["errors"]}
                for o in outcomes if o["failed"]]
    coverage_records = sorted((o["record"] for o in outcomes if not o["failed"] and o["kind"] == "coverage"),
                              key=lambda r: (r["arm"], r["seed"]))
    selection_records = sorted((o["record"] for o in outcomes if not o["failed"] and o["kind"] == "selection"),
                               key=lambda r: (r["truth"], r["seed"]))
    coverage = [summarise_coverage([r for r in coverage_records if r["arm"] == arm.key], arm) for arm in COVERAGE_ARMS]
    selection = summarise_selection(selection_records)
    targets = {}
    for arm in coverage:
        for name, met in arm.get("targets_met", {}).items():
            targets[f"{arm['arm']['key']}: {name} coverage in target"] = met
    targets.update(selection["targets_met"])
    payload = {
        "benchmark": "calibration",
        "command": "python benchmarks/calibration.py" + (" --quick" if quick else "")
                   + (f" --realism {args.realism}" if args.realism != "ideal" else "")
                   + (" --texture-slope" if args.texture_slope else "")
                   + (f" --truths {args.truths}" if args.truths else "")
                   + (f" --selection-only --selection-seeds {n_sel}" if args.selection_only else ""),
        "arguments": {"coverage_seeds": n_cov, "tabulated_seeds": n_tab, "selection_seeds": n_sel,
                      "workers": args.workers, "realism": args.realism, "texture_slope": args.texture_slope,
                      "truths": [t.key for t in truths]},
        "machine": machine(),
        "git": git_state(),
        "design": {
            "coverage_protocol": "protocols/oren-nayar-fig16-plaster.toml with the camera every 10 deg "
                                 "(view = -80..80 step 10 at theta_i = 30, 45, 60 deg; reference standard at "
                                 "(30, 0, -10), (45, 0, -10), (60, 0, -10))",
            "selection_protocol": selection_protocol(),
            "noise": (f"realism {args.realism} (gonio.cli.run.emulated_rig): CCD shot, read and dark noise, PRNU, "
                      "lamp flicker and drift on, lamp monitor on, lamp already warm"
                      + ("; the lab rig's misalignment, stray light, non-linearity, beam profile, texture, wedge, "
                         "remounting and monitor mismatch, fitted with the calibration per incidence and the rig's "
                         "errors as parameters" if args.realism == "lab" else "")),
            "reference_reflectance": REFERENCE_REFLECTANCE,
            "prior": {k: list(v) for k, v in PRIOR.items()},
            "mcmc": mcmc_design(),
            "sbc_draws": SBC_DRAWS, "rank_bins": RANK_BINS, "rank_band": RANK_BAND,
            "coverage_targets": {k: list(v) for k, v in COVERAGE_TARGETS.items()},
            "selection_target": SELECTION_TARGET,
            "candidates": [{"model": n, "fixed": f} for n, f in CANDIDATES],
            "selection_jitter": SELECTION_JITTER,
            "rig_errors": rig_errors(),
            "truths": [{"key": t.key, "spec": t.spec, "family": t.family} for t in truths],
        },
        "coverage": coverage,
        "selection": selection,
        "failures": failures,
        "targets_met": targets,
        "all_targets_met": all(targets.values()) if targets else False,
        "noise_free": noise_free,
        "sessions": sessions,
        "wall_s": float(sum(x["wall_s"] for x in sessions)),
        "coverage_records": coverage_records,
        "selection_records": selection_records,
    }
    payload = _clean(payload)
    write_json("calibration" + suffix, payload)
    draw_charts(payload, suffix)
    print_tables(payload)
    if failures:
        print(f"{len(failures)} run(s) failed twice; see 'failures' in the JSON")
    if args.records is None and not failures:
        records_path.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""MCMC moves and ensemble sizes: time to convergence, ESS per second, posterior unchanged.

``gonio fit`` stops when the chain is 50 autocorrelation times long and every
rank-normalised split R-hat (each walker a chain, after burn-in) is below 1.01. R-hat
needs about 100 tau of steps whatever the ensemble, so the time to convergence is set by
the autocorrelation time tau (in steps) of the move and the cost of a step. This script
runs gonio's sampler (``sample_posterior``, the same call as ``gonio fit``) with emcee's
moves and mixtures of them, for 16 to 256 walkers and three seeds each, on four problems:

* ``fig16``: the Fig 16 recording of the shipped protocol measured on the embedded
  emulator, ``--model oren-nayar --fix ir_weight=1`` (90 values, correlated errors, a
  calibration prior on ``scale``; the fit of ``gonio fit ... --report``);
* ``gaussian``, ``bound``, ``skewed``: the problems of benchmarks/fit_time_accuracy.py
  (near-Gaussian; sigma piled at its bound 0; a skewed Minnaert posterior from 4 values);
* ``rig``: the fit of ``gonio demo`` (seed 0): both protocols measured on the default
  (lab) emulated rig, ``oren-nayar-tabulated`` through the apertures with the rig's seven
  alignment parameters and its stray light free and the calibration per incidence (126
  values, 11 parameters, alignment pairs correlated at 0.96-0.99). Its model costs about
  0.4 ms per walker, so it runs at 24 and 32 walkers only (22 is emcee's least for 11 parameters), against a reference of DE (32 walkers
  x 20000 steps, burn-in 2000; the stretch move's reference would take hours).

Moves (gonio.fitting.moves): ``stretch`` (emcee's default, the affine-invariant stretch
move), ``de`` (differential evolution), ``de+snooker`` (DE 0.8 + DE snooker 0.2, the
mixture emcee's documentation shows), ``de+stretch`` (0.5 each), ``gaussian`` (random-walk
Metropolis with the least-squares covariance times 2.38^2/d; DE where that covariance is
undetermined), ``gaussian+de``, ``gaussian+stretch`` (0.5 each), ``laplace+de``
(independence proposals from the least-squares Laplace approximation, a Student t, 0.5 +
DE 0.5; DE where that covariance is undetermined).

Per run: steps and wall time to convergence (the checks included), largest tau, smallest
bulk ESS (ArviZ) and ESS per second, and against a reference chain of each problem
(emcee's stretch move, 256 walkers x 20000 steps, burn-in 2000): the largest shift of a
posterior median and the largest relative change of a posterior sd, in reference sd, and
the largest error of a 95 % interval endpoint, in reference sd. Requirements for a
default: median within 0.5 sd, sd within 20 %, interval error no worse than the stretch
move's at the same ensemble size.

Also the cost of the loop itself: 1000 DE steps of the Fig 16 posterior with 32 walkers
driven by ``emcee.EnsembleSampler`` (in pieces of 100 steps, as between convergence
checks) and by gonio's ``EnsembleChain``, which gives the same chain bit for bit
(``--loop-only`` measures only that).

Writes docs/benchmarks/moves.json and moves.png. Run: ``python benchmarks/bench_moves.py``
(about 25 minutes on 2 cores shared with other jobs); ``--moves a,b`` re-measures those
move sets only and replaces their rows in the existing moves.json (same references).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, write_json  # noqa: E402

PROTOCOL = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
GONIO = Path(sys.executable).with_name("gonio")
MOVES = ("stretch", "de", "de+snooker", "de+stretch", "gaussian", "gaussian+de", "gaussian+stretch", "laplace+de")
WALKERS = (16, 32, 64, 128, 256)
SEEDS = (0, 1, 2)
REFERENCE_WALKERS, REFERENCE_STEPS, REFERENCE_BURN = 256, 20000, 2000
#: Problems whose reference chain is not the stretch move's default one: (moves, walkers).
REFERENCE_OF = {"rig": ("de", 32)}
#: The problems, in the order they run.
PROBLEMS = ("fig16", "gaussian", "bound", "skewed", "rig")
#: Problems run at these ensemble sizes only (a costly model).
WALKERS_OF = {"rig": (24, 32)}


def fig16_problem(scratch: Path):
    """The Fig 16 recording fitted as ``gonio fit REC --model oren-nayar --fix ir_weight=1``."""
    from gonio.analysis import load_data
    from gonio.fitting import FitProblem

    recording = scratch / "plaster"
    subprocess.run([str(GONIO), "run", str(PROTOCOL), "--out", str(recording)], check=True, capture_output=True)
    dataset, priors = load_data(recording)
    return FitProblem("oren-nayar", dataset, {"ir_weight": 1.0}, {}, False), priors


def rig_problem(scratch: Path):
    """The fit of ``gonio demo`` at seed 0 (module docstring)."""
    from gonio.cli.demo import RIG_ERRORS, measure_demo
    from gonio.fitting import FitProblem

    dataset, priors = measure_demo(scratch / "demo", seed=0).fit_inputs("per-incidence")
    return FitProblem("oren-nayar-tabulated", dataset, None, None, None, RIG_ERRORS["alignment"],
                      RIG_ERRORS["stray_light"]), priors


def reference(problem, start, priors, name: str = "") -> np.ndarray:
    """Samples of the reference chain (fixed length, no early stop; the stretch move with
    256 walkers unless :data:`REFERENCE_OF` names another)."""
    from gonio.fitting.mcmc import ConvergenceWarning, sample_posterior

    moves, walkers = REFERENCE_OF.get(name, ("stretch", REFERENCE_WALKERS))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        chain, _ = sample_posterior(problem, start, priors=priors, n_walkers=walkers,
                                    max_steps=REFERENCE_STEPS, tau_multiple=1e9, seed=12345, moves=moves)
    return chain.chain[REFERENCE_BURN:].reshape(-1, len(problem.free))


def compare(samples: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    """Median shift, sd change and 95 % endpoint error against the reference [reference sd]."""
    sd = ref.std(axis=0)
    ends = np.percentile(samples, [2.5, 97.5], axis=0)
    ref_ends = np.percentile(ref, [2.5, 97.5], axis=0)
    return {"median_shift_sd": float(np.max(np.abs(np.median(samples, 0) - np.median(ref, 0)) / sd)),
            "sd_change": float(np.max(np.abs(samples.std(axis=0) / sd - 1.0))),
            "interval_error_sd": float(np.max(np.abs(ends - ref_ends) / sd))}


def runs(name: str, problem, start, priors, ref: np.ndarray, moves, walkers, seeds) -> list[dict]:
    from gonio.fitting.mcmc import sample_posterior

    rows = []
    for move in moves:
        for n_walkers in walkers:
            for seed in seeds:
                began = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # ArviZ on ensembles of more walkers than draws
                    chain, _ = sample_posterior(problem, start, priors=priors, n_walkers=n_walkers, seed=seed,
                                                moves=move)
                wall = time.perf_counter() - began
                ess = min(d["ess_bulk"] for d in chain.diagnostics.values())
                row = {"problem": name, "moves": move, "walkers": n_walkers, "seed": seed, "wall_s": wall,
                       "steps": chain.n_steps, "converged": chain.converged, "max_tau": float(np.max(chain.tau)),
                       "min_ess_bulk": ess, "ess_per_s": ess / wall,
                       "acceptance": float(chain.acceptance_fraction.mean()),
                       **compare(chain.samples(), ref)}
                rows.append(row)
                print(f"  {name:8s} {move:16s} {n_walkers:4d} walkers seed {seed}: {row['steps']:5d} steps "
                      f"{wall:6.2f} s tau {row['max_tau']:5.1f} ESS/s {row['ess_per_s']:7.0f} "
                      f"median {row['median_shift_sd']:.2f} sd {row['sd_change']:.2f} interval {row['interval_error_sd']:.2f}",
                      flush=True)
    return rows


def loop_overhead(problem, start, priors, steps: int = 1000, walkers: int = 32, repeats: int = 3) -> dict:
    """CPU time [s] of ``steps`` DE steps of the Fig 16 posterior driven by
    ``emcee.EnsembleSampler`` (run in pieces of 100 steps, as between convergence checks)
    and by gonio's :class:`~gonio.fitting.ensemble.EnsembleChain` (the same chain, bit for
    bit), least of ``repeats``, and the time of the log posterior alone in the latter."""
    import emcee

    from gonio.fitting.ensemble import EnsembleChain
    from gonio.fitting.mcmc import LogPosterior, resolve_priors
    from gonio.fitting.moves import VectorisedDEMove

    posterior = LogPosterior(problem, resolve_priors(problem, start.values, priors))
    centre = np.array([start.values[n] for n in problem.free])
    spread = np.array([0.1 * start.stderr[n] for n in problem.free])
    coords = centre + spread * np.random.default_rng(0).standard_normal((walkers, centre.size))
    emcee_s, gonio_s, model_s = [], [], []
    for _ in range(repeats):
        sampler = emcee.EnsembleSampler(walkers, centre.size, posterior.batch, vectorize=True,
                                        moves=VectorisedDEMove(), )
        sampler._moves[0].log_prob_batch = posterior.batch  # the vectorised acceptance, as gonio
        state = emcee.State(coords, random_state=np.random.RandomState(1).get_state())
        began = time.process_time()
        for _ in range(steps // 100):
            state = sampler.run_mcmc(state, 100, progress=False)
        emcee_s.append(time.process_time() - began)
        posterior.model_seconds = 0.0
        chain = EnsembleChain(posterior.batch, [(VectorisedDEMove(), 1.0)], coords, np.random.RandomState(1))
        began = time.process_time()
        for _ in range(steps // 100):
            chain.run(100)
        gonio_s.append(time.process_time() - began)
        model_s.append(posterior.model_seconds)
    return {"steps": steps, "walkers": walkers, "emcee_sampler_cpu_s": min(emcee_s),
            "gonio_loop_cpu_s": min(gonio_s), "likelihood_wall_s_in_gonio_loop": min(model_s),
            "ratio_emcee_over_gonio": min(emcee_s) / min(gonio_s)}


def summarise(rows: list[dict]) -> list[dict]:
    """Medians over seeds of every (problem, moves, walkers), and the worst posterior errors."""
    out = []
    keys = sorted({(r["problem"], r["moves"], r["walkers"]) for r in rows}, key=lambda k: (k[0], MOVES.index(k[1]), k[2]))
    for problem, move, walkers in keys:
        mine = [r for r in rows if (r["problem"], r["moves"], r["walkers"]) == (problem, move, walkers)]
        out.append({"problem": problem, "moves": move, "walkers": walkers,
                    "all_converged": all(r["converged"] for r in mine),
                    "median_wall_s": statistics.median(r["wall_s"] for r in mine),
                    "median_steps": statistics.median(r["steps"] for r in mine),
                    "median_tau": statistics.median(r["max_tau"] for r in mine),
                    "median_ess_per_s": statistics.median(r["ess_per_s"] for r in mine),
                    "ms_per_step": 1e3 * statistics.median(r["wall_s"] / r["steps"] for r in mine),
                    "worst_median_shift_sd": max(r["median_shift_sd"] for r in mine),
                    "worst_sd_change": max(r["sd_change"] for r in mine),
                    "worst_interval_error_sd": max(r["interval_error_sd"] for r in mine)})
    return out


def chart(summary: list[dict], path: Path) -> None:
    """Steps and wall time to convergence against walkers, one panel pair per problem (the
    steps do not depend on the machine's load; the wall time does)."""
    from matplotlib.figure import Figure

    problems = list(dict.fromkeys(s["problem"] for s in summary))
    fig = Figure(figsize=(3.4 * len(problems), 6.4), layout="constrained")
    axes = fig.subplots(2, len(problems), squeeze=False)
    for column, problem in enumerate(problems):
        for k, move in enumerate(MOVES):
            mine = [s for s in summary if s["problem"] == problem and s["moves"] == move]
            if not mine:
                continue
            style = dict(color=f"C{k}", marker="o", ms=3, lw=1.5 if move in ("stretch", "de") else 0.8, label=move)
            axes[0, column].plot([s["walkers"] for s in mine], [s["median_steps"] for s in mine], **style)
            axes[1, column].plot([s["walkers"] for s in mine], [s["median_wall_s"] for s in mine], **style)
        axes[0, column].set_title(problem, fontsize=10)
        for row in (0, 1):
            axes[row, column].set(xscale="log", yscale="log")
            axes[row, column].set_xticks(WALKERS, [str(w) for w in WALKERS])
            axes[row, column].minorticks_off()
            axes[row, column].grid(alpha=0.3)
        axes[1, column].set_xlabel("walkers")
    axes[0, 0].set_ylabel("steps to convergence")
    axes[1, 0].set_ylabel("wall time to convergence [s]")
    axes[0, 0].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", default=",".join(PROBLEMS))
    parser.add_argument("--moves", default=",".join(MOVES))
    parser.add_argument("--walkers", default=",".join(map(str, WALKERS)))
    parser.add_argument("--chart-only", action="store_true", help="redraw moves.png from moves.json")
    parser.add_argument("--loop-only", action="store_true",
                        help="measure the loop overhead only and store it in moves.json")
    args = parser.parse_args()
    if args.chart_only:
        import json

        chart(json.loads((OUT / "moves.json").read_text())["summary"], OUT / "moves.png")
        return 0
    if args.loop_only:
        import json

        from gonio.fitting import fit_least_squares

        with tempfile.TemporaryDirectory(prefix="gonio-moves-") as scratch:
            problem, priors = fig16_problem(Path(scratch))
            loop = loop_overhead(problem, fit_least_squares(problem, seed=0, priors=priors), priors)
        loop["load_average"] = os.getloadavg()[0]
        payload = json.loads((OUT / "moves.json").read_text())
        payload["loop"] = loop
        write_json("moves", payload)
        print(loop)
        return 0
    from fit_time_accuracy import problems as accuracy_problems

    from gonio.fitting import fit_least_squares
    from gonio.fitting.diagnostics import arviz

    arviz()  # imported before any run: no import time in the measurements
    load_before = os.getloadavg()[0]
    moves = args.moves.split(",")
    problems = args.problems.split(",")
    walkers = [int(w) for w in args.walkers.split(",")]
    rows, references = [], {}
    with tempfile.TemporaryDirectory(prefix="gonio-moves-") as scratch:
        others = accuracy_problems()
        for name in problems:
            if name in ("fig16", "rig"):
                problem, priors = (fig16_problem if name == "fig16" else rig_problem)(Path(scratch))
            else:
                problem, priors = others[name], None
            priors = problem.priors_with_defaults(priors)  # the rig's alignment priors, as gonio.fitting.fit
            start = fit_least_squares(problem, seed=0, priors=priors)
            began = time.perf_counter()
            ref = reference(problem, start, priors, name)
            references[name] = {"free": list(problem.free), "median": np.median(ref, 0).tolist(),
                                "sd": ref.std(axis=0).tolist(), "seconds": time.perf_counter() - began}
            print(f"{name}: reference {references[name]}", flush=True)
            rows += runs(name, problem, start, priors, ref, moves, WALKERS_OF.get(name, walkers), SEEDS)
    loads = [load_before, os.getloadavg()[0]]
    previous = OUT / "moves.json"
    if previous.exists() and (set(moves) != set(MOVES) or set(problems) != set(PROBLEMS) or args.walkers != ",".join(map(str, WALKERS))):
        # a partial run: keep the rows and references of the (problem, moves, walkers) it did not run
        import json

        kept = json.loads(previous.read_text())
        ran = {(r["problem"], r["moves"], r["walkers"]) for r in rows}
        rows = [r for r in kept["runs"] if (r["problem"], r["moves"], r["walkers"]) not in ran] + rows
        references = {**kept["reference"]["problems"], **references}
        loads = kept["load_average_before_after"] + loads
    summary = summarise(rows)
    with tempfile.TemporaryDirectory(prefix="gonio-moves-") as scratch:
        problem, priors = fig16_problem(Path(scratch))
        loop = loop_overhead(problem, fit_least_squares(problem, seed=0, priors=priors), priors)
    path = write_json("moves", {
        "load_average_before_after": loads,
        "benchmark": "moves",
        "command": "python benchmarks/bench_moves.py",
        "machine": machine(),
        "reference": {"moves": "stretch", "walkers": REFERENCE_WALKERS, "steps": REFERENCE_STEPS,
                      "burn_in": REFERENCE_BURN, "problems": references},
        "summary": summary,
        "loop": loop,
        "runs": rows,
    })
    chart(summary, OUT / "moves.png")
    for s in summary:
        print(f"{s['problem']:8s} {s['moves']:16s} {s['walkers']:4d}: {s['median_wall_s']:6.2f} s {s['median_steps']:6.0f} steps "
              f"tau {s['median_tau']:5.1f} ESS/s {s['median_ess_per_s']:7.0f} {s['ms_per_step']:.2f} ms/step; worst median "
              f"{s['worst_median_shift_sd']:.2f} sd {s['worst_sd_change']:.2f} interval {s['worst_interval_error_sd']:.2f}"
              + ("" if s["all_converged"] else " NOT ALL CONVERGED"))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

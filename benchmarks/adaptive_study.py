"""Adaptive runs against fixed designs on the emulated rig: the instrument time each needs
for a target width of sigma's 95 % interval.

The sample is ``oren-nayar-exact`` (sigma = 30 deg, rho = 0.9, the plaster) on the default
(realistic) emulated rig; every recording is fitted as an adaptive run decides
(:func:`gonio.adaptive.fit_posterior`: ``oren-nayar-tabulated`` by least squares, calibration
per incidence, the alignment and the stray light free, uniform priors sigma 10-45 deg and
rho 0.5-1; intervals value +- 1.96 standard errors).

- **Fixed designs**: ``gonio design`` at budgets from 320 s to 500 s (``FIXED_BUDGETS``),
  ``--seeds`` seeds each (emulator seeds). For a target width the best fixed design's time
  is the smallest budget whose median measured width meets it (a user with a fixed design
  must choose the budget before measuring; this is the best they could have chosen), in
  recorded instrument time less the lamp's warm-up.
- **The shipped protocols** (the measured front of the issue "Measurement design"): Fig 16,
  Fig 16 with every second view, Fig 16 at one incidence (45 deg), Fig 17, Fig 19 and
  CUReT 205, ``--fixed-seeds`` seeds each, fitted alike (with one common calibration where
  the protocol reads no reference standard at every incidence: Fig 17 and CUReT 205 read
  none, so their rho is relative only).
- **Adaptive runs**: ``gonio run START --adaptive --until sigma=W --budget 900s`` with START
  the design at 300 s reading the reference standard at the lamp angles of the design at
  600 s (``gonio design --reference-at``), ``--seeds`` seeds per target; the recorded time
  at the stop, whether the target was met, and the final interval's coverage of the truth.

The target of the issue "Measurement design": an adaptive run stops within 1.3x of the
instrument time the best fixed design needed for that width.

Run: ``python benchmarks/adaptive_study.py --seeds 20`` (``--first-seed`` to share the seeds
between processes; runs are appended to
``docs/benchmarks/adaptive_study.jsonl`` as they finish, so an interrupted study resumes;
``--part fixed``, ``--part shipped`` or ``--part adaptive`` runs one part, e.g. in two
processes); writes
``docs/benchmarks/adaptive_study.json`` and ``.png``.
"""
from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from _common import OUT, ROOT, machine, record_on_emulator, wilson, write_json

MODEL = "oren-nayar-tabulated"
TRUTH_SPEC = "oren-nayar-exact:rho=0.9,sigma=30"
TRUTH = {"sigma": 30.0, "rho": 0.9}
PRIORS = {"sigma": (10.0, 45.0), "rho": (0.5, 1.0)}
#: Target 95 % widths of sigma [deg].
TARGETS = (0.15, 0.08)
#: Budgets of the fixed designs [s].
FIXED_BUDGETS = (320.0, 340.0, 360.0, 380.0, 400.0, 435.0, 470.0, 500.0)
START_BUDGET = 300.0
ADAPTIVE_BUDGET = 900.0
RECORDS = OUT / "adaptive_study.jsonl"


def settings(target: float, seed: int, calibration: str = "per-incidence"):
    from gonio.adaptive import AdaptiveSettings

    return AdaptiveSettings(MODEL, {"sigma": target}, ADAPTIVE_BUDGET, dict(PRIORS), seed=seed,
                            calibration=calibration)


def shipped_protocols() -> dict[str, str]:
    """``{name: protocol text}`` of the shipped protocols and Fig 16's thinned variants."""
    def read(name: str) -> str:
        return (ROOT / "protocols" / f"{name}.toml").read_text()

    fig16 = read("oren-nayar-fig16-plaster")
    return {"Fig 16": fig16, "Fig 16, every second view": fig16.replace("step = 5", "step = 10"),
            "Fig 16, theta_i = 45 only": fig16.replace("theta_i = [30, 45, 60]", "theta_i = 45"),
            "Fig 17": read("oren-nayar-fig17-sandpaper"), "Fig 19": read("oren-nayar-fig19-off-plane"),
            "CUReT 205": read("curet-205")}


def start_protocol() -> str:
    """The adaptive runs' starting protocol: the 300-s design, reading the reference
    standard at the lamp angles of the 600-s design too."""
    from gonio import design as D

    wide = D.design(MODEL, PRIORS, 600.0)
    angles = sorted({p[0] for p in wide.points})
    return D.design_protocol_text(D.design(MODEL, PRIORS, START_BUDGET, reference_at=angles))


def measure(text: str, folder: Path, seed: int, extend=None):
    from gonio import protocols

    return record_on_emulator(protocols.loads(text, source="study"), TRUTH_SPEC, seed, folder,
                              name="adaptive-study", extend=extend)


def outcome(posterior) -> dict[str, Any]:
    return {n: {"value": posterior.values[n], "width": posterior.widths[n],
                "in95": bool(abs(posterior.values[n] - TRUTH[n]) <= posterior.widths[n] / 2)} for n in TRUTH}


def run_fixed(budget: float, seed: int, scratch: Path) -> dict[str, Any]:
    from gonio import adaptive, design as D, protocols

    text = D.design_protocol_text(D.design(MODEL, PRIORS, budget))
    folder = scratch / f"fixed-{budget:g}-{seed}"
    start = time.perf_counter()
    run = measure(text, folder, seed)
    posterior = adaptive.fit_posterior(folder, settings(TARGETS[0], seed))
    shutil.rmtree(folder, ignore_errors=True)
    return {"kind": "fixed", "budget": budget, "seed": seed, "points": run.measured,
            "planned_seconds": protocols.plan(protocols.loads(text)).estimated_seconds,
            "recorded_seconds": run.instrument_seconds - run.warm_up_seconds, "fit": outcome(posterior),
            "redchi": posterior.redchi, "wall_seconds": time.perf_counter() - start}


def run_shipped(name: str, seed: int, scratch: Path) -> dict[str, Any]:
    from gonio import adaptive, protocols

    text = shipped_protocols()[name]
    protocol = protocols.loads(text, source=name)
    calibrated = protocol.reference is not None and {p.theta_i for p in protocols.plan(protocol).points} <= {
        float(g[0]) for g in protocol.reference.geometries}
    folder = scratch / f"shipped-{seed}"
    start = time.perf_counter()
    run = measure(text, folder, seed)
    posterior = adaptive.fit_posterior(folder, settings(TARGETS[0], seed, "per-incidence" if calibrated else "common"))
    shutil.rmtree(folder, ignore_errors=True)
    return {"kind": "shipped", "protocol": name, "seed": seed, "points": run.measured, "calibrated": calibrated,
            "planned_seconds": protocols.plan(protocol).estimated_seconds,
            "recorded_seconds": run.instrument_seconds - run.warm_up_seconds, "fit": outcome(posterior),
            "redchi": posterior.redchi, "wall_seconds": time.perf_counter() - start}


def run_adaptive(target: float, seed: int, scratch: Path, start_text: str) -> dict[str, Any]:
    from gonio import adaptive, protocols

    folder = scratch / f"adaptive-{target:g}-{seed}"
    start = time.perf_counter()
    decider = adaptive.AdaptiveRun(folder, protocols.loads(start_text, source="start"), settings(target, seed))
    run = measure(start_text, folder, seed, extend=decider)
    final = decider.last
    shutil.rmtree(folder, ignore_errors=True)
    return {"kind": "adaptive", "target": target, "seed": seed, "points": run.measured, "batches": decider.batches,
            "planned_seconds": protocols.plan(decider.protocol).estimated_seconds,
            "recorded_seconds": run.instrument_seconds - run.warm_up_seconds, "fit": outcome(final),
            "reached": final.widths["sigma"] <= target, "redchi": final.redchi,
            "wall_seconds": time.perf_counter() - start}



def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The fixed designs' front, the best fixed design per target, the adaptive runs."""
    fixed_rows = []
    for budget in FIXED_BUDGETS:
        mine = [r for r in records if r["kind"] == "fixed" and r["budget"] == budget]
        if mine:
            fixed_rows.append({"budget": budget, "seeds": len(mine),
                               "recorded_seconds": float(np.median([r["recorded_seconds"] for r in mine])),
                               "sigma_width_median": float(np.median([r["fit"]["sigma"]["width"] for r in mine])),
                               "sigma_coverage": sum(r["fit"]["sigma"]["in95"] for r in mine) / len(mine),
                               "points": int(np.median([r["points"] for r in mine]))})
    shipped_rows = []
    for name in shipped_protocols():
        mine = [r for r in records if r["kind"] == "shipped" and r["protocol"] == name]
        if mine:
            row = {"protocol": name, "seeds": len(mine), "calibrated": mine[0]["calibrated"],
                   "points": int(np.median([r["points"] for r in mine])),
                   "planned_seconds": float(np.median([r["planned_seconds"] for r in mine])),
                   "recorded_seconds": float(np.median([r["recorded_seconds"] for r in mine]))}
            for parameter in TRUTH:
                covered = sum(r["fit"][parameter]["in95"] for r in mine)
                row[parameter] = {"width_median": float(np.median([r["fit"][parameter]["width"] for r in mine])),
                                  "coverage": covered / len(mine), "coverage_wilson": wilson(covered, len(mine))}
            shipped_rows.append(row)
    targets = []
    for target in TARGETS:
        best = next((row for row in fixed_rows if row["sigma_width_median"] <= target), None)
        mine = [r for r in records if r["kind"] == "adaptive" and r["target"] == target]
        if not mine:
            continue
        seconds = float(np.median([r["recorded_seconds"] for r in mine]))
        covered = sum(r["fit"]["sigma"]["in95"] for r in mine)
        targets.append({
            "target": target, "seeds": len(mine), "reached": sum(r["reached"] for r in mine),
            "adaptive_seconds_median": seconds,
            "adaptive_seconds_range": [min(r["recorded_seconds"] for r in mine),
                                       max(r["recorded_seconds"] for r in mine)],
            "batches_median": float(np.median([r["batches"] for r in mine])),
            "sigma_width_median": float(np.median([r["fit"]["sigma"]["width"] for r in mine])),
            "sigma_coverage": covered / len(mine), "sigma_coverage_wilson": wilson(covered, len(mine)),
            "rho_coverage": sum(r["fit"]["rho"]["in95"] for r in mine) / len(mine),
            "best_fixed_budget": best["budget"] if best else None,
            "best_fixed_seconds": best["recorded_seconds"] if best else None,
            "ratio": seconds / best["recorded_seconds"] if best else None,
        })
    return {"fixed": fixed_rows, "shipped": shipped_rows, "targets": targets}


def chart(summary: dict[str, Any], records: list[dict[str, Any]], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.8))
    ax = fig.add_subplot(1, 1, 1)
    fixed = [r for r in records if r["kind"] == "fixed"]
    ax.scatter([r["recorded_seconds"] for r in fixed], [r["fit"]["sigma"]["width"] for r in fixed], s=8,
               color="C1", alpha=0.4, label="fixed designs (each seed)")
    ax.plot([row["recorded_seconds"] for row in summary["fixed"]],
            [row["sigma_width_median"] for row in summary["fixed"]], "s-", color="C1", label="fixed designs (median)")
    shown = [row for row in summary["shipped"] if row["sigma"]["width_median"] < 5.0]  # undetermined ones left out
    for k, row in enumerate(shown):
        ax.plot(row["recorded_seconds"], row["sigma"]["width_median"], "D", color="C0",
                label="shipped protocols (median; coverage)" if k == 0 else None)
        ax.annotate(f"{row['protocol']} ({row['sigma']['coverage']:.1f})", (row["recorded_seconds"],
                    row["sigma"]["width_median"]), fontsize=6, xytext=(4, 2), textcoords="offset points")
    for k, target in enumerate(TARGETS):
        mine = [r for r in records if r["kind"] == "adaptive" and r["target"] == target]
        ax.scatter([r["recorded_seconds"] for r in mine], [r["fit"]["sigma"]["width"] for r in mine], s=14,
                   marker="o", color=f"C{k + 2}", label=f"adaptive, until sigma width {target:g} deg")
        ax.axhline(target, color=f"C{k + 2}", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("recorded instrument time after the lamp's warm-up [s]")
    ax.set_ylabel("95 % width of sigma [deg]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"Emulated rig (default realism), sample {TRUTH_SPEC}, fitted with {MODEL}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds of the adaptive runs (default 20)")
    parser.add_argument("--fixed-seeds", type=int, default=10, help="seeds of each fixed design (default 10)")
    parser.add_argument("--part", choices=["fixed", "shipped", "adaptive", "all"], default="all")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed to run (to share the seeds between two processes)")
    args = parser.parse_args()
    import gonio

    gonio.brdf("oren-nayar-exact", 45.0, 0.0, np.array([20.0]), np.array([0.0]), **TRUTH)  # compile first
    records = list(map(json.loads, RECORDS.read_text().splitlines())) if RECORDS.exists() else []
    done = {(r["kind"], r.get("budget", r.get("target", r.get("protocol"))), r["seed"]) for r in records}
    todo = []
    if args.part in ("fixed", "all"):
        todo += [("fixed", b, s) for s in range(args.first_seed, args.fixed_seeds) for b in FIXED_BUDGETS]
    if args.part in ("shipped", "all"):
        todo += [("shipped", name, s) for s in range(args.first_seed, args.fixed_seeds)
                 for name in shipped_protocols()]
    if args.part in ("adaptive", "all"):
        todo += [("adaptive", t, s) for s in range(args.first_seed, args.seeds) for t in TARGETS]
    todo = [job for job in todo if job not in done]
    print(f"{len(todo)} runs to do", flush=True)
    start_text = start_protocol()
    scratch = Path(tempfile.mkdtemp(prefix="gonio-adaptive-study-"))
    begun = time.perf_counter()
    try:
        for k, (kind, value, seed) in enumerate(todo, start=1):
            record = (run_fixed(value, seed, scratch) if kind == "fixed"
                      else run_shipped(value, seed, scratch) if kind == "shipped"
                      else run_adaptive(value, seed, scratch, start_text))
            with RECORDS.open("a") as sink:
                sink.write(json.dumps(record) + "\n")
            elapsed = time.perf_counter() - begun
            print(f"[{k}/{len(todo)}] {kind} {value} seed {seed}: sigma width {record['fit']['sigma']['width']:.3f}, "
                  f"{record['recorded_seconds']:.0f} s (eta {elapsed / k * (len(todo) - k) / 60:.1f} min)", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    records = list(map(json.loads, RECORDS.read_text().splitlines()))
    summary = summarise(records)
    for row in summary["fixed"]:
        print(f"fixed {row['budget']:5.0f} s: {row['seeds']} seeds, {row['recorded_seconds']:.0f} s recorded, "
              f"sigma width {row['sigma_width_median']:.3f}, coverage {row['sigma_coverage']:.2f}")
    for row in summary["shipped"]:
        print(f"{row['protocol']:<26} {row['seeds']} seeds, {row['recorded_seconds']:.0f} s recorded, sigma width "
              f"{row['sigma']['width_median']:.3f} (coverage {row['sigma']['coverage']:.2f}), rho width "
              f"{row['rho']['width_median']:.4f} (coverage {row['rho']['coverage']:.2f})")
    for row in summary["targets"]:
        print(f"target {row['target']:g}: adaptive {row['adaptive_seconds_median']:.0f} s "
              f"({row['reached']}/{row['seeds']} reached, coverage {row['sigma_coverage']:.2f}); best fixed "
              f"{row['best_fixed_seconds']} s; ratio {row['ratio']}")
    write_json("adaptive_study", {"model": MODEL, "truth": TRUTH_SPEC, "priors": PRIORS, "targets": TARGETS,
                                  "start_protocol": start_text, **summary, "machine": machine()})
    chart(summary, records, OUT / "adaptive_study.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

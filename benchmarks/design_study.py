"""Designed against shipped protocols on the emulated rig: measured widths, coverage and time.

The expected front of ``bench_design.py`` is the Laplace approximation at the truth. This
study measures what a user gets: every protocol is run on the default (realistic) emulated
rig with ``oren-nayar-exact`` (sigma = 30 deg, rho = 0.9, the plaster) as the sample, over
``--seeds`` emulator seeds, and each recording is fitted with ``oren-nayar-tabulated`` by
least squares, with uniform priors sigma 10-45 deg and rho 0.5-1 (the design's), twice:
as ``gonio fit REC`` comes (one calibration, no rig errors, the extra noise ``auto``), and
with the remedies for a real rig (``--calibration per-incidence --alignment all
--stray-light``, as ``gonio demo``). Per protocol and fit: the median 95 % interval width
of sigma and rho (the least-squares intervals, value +- 1.96 standard errors: an MCMC with
ten alignment parameters on the tabulated model takes minutes per seed), how often the
interval holds the truth (coverage, with a Wilson 95 % interval) and the reduced
chi-square; and the time: the plan's estimate against the recording's instrument time
less its lamp warm-up.

Protocols: the shipped Fig 16, Fig 16 at one incidence (45 deg), and ``gonio design`` for
``oren-nayar-tabulated`` (robust to the alignment errors, its default) at 300 s, at
Fig 16's estimated time and at 600 s.

Run: ``python benchmarks/design_study.py --seeds 10`` (about an hour on one core: the fit
with the rig's errors takes about a minute; runs are appended to
``docs/benchmarks/design_study.jsonl`` as they finish, so an interrupted study resumes);
writes ``docs/benchmarks/design_study.json`` and ``.png``.
"""
from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from _common import OUT, ROOT, machine, record_on_emulator, wilson, write_json

MODEL = "oren-nayar-tabulated"
TRUTH_SPEC = "oren-nayar-exact:rho=0.9,sigma=30"
TRUTH = {"sigma": 30.0, "rho": 0.9}
PRIORS = {"sigma": (10.0, 45.0), "rho": (0.5, 1.0)}
FIG16 = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
RECORDS = OUT / "design_study.jsonl"
#: The fits of every recording: ``gonio fit REC`` as it comes (one calibration, no rig
#: errors, the extra noise ``auto``) and with the remedies docs/fitting.md gives for a
#: real rig (``--calibration per-incidence --alignment all --stray-light``, as ``gonio demo``).
FITS = {"plain": {}, "rig errors": {"calibration": "per-incidence", "alignment": "all", "stray_light": True}}


def protocols_studied() -> dict[str, str]:
    """``{name: protocol text}`` of every protocol of the study."""
    from gonio import design as D
    from gonio import protocols as P

    fig16 = FIG16.read_text()
    texts = {"Fig 16 (shipped)": fig16,
             "Fig 16, theta_i = 45 only": fig16.replace("theta_i = [30, 45, 60]", "theta_i = 45")}
    fig16_seconds = P.plan(P.loads(fig16)).estimated_seconds
    for label, budget in (("designed, 300 s", 300.0), ("designed, Fig 16's time", fig16_seconds),
                          ("designed, 600 s", 600.0)):
        texts[label] = D.design_protocol_text(D.design(MODEL, PRIORS, budget))
    return texts


def run_one(name: str, text: str, seed: int, scratch: Path) -> dict[str, Any]:
    """Measure ``text`` on the emulated rig with seed ``seed``, fit it, and record the outcome."""
    import gonio
    from gonio import protocols
    from gonio.fitting.priors import Uniform

    protocol = protocols.loads(text, source=name)
    folder = scratch / f"run-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    start = time.perf_counter()
    run = record_on_emulator(protocol, TRUTH_SPEC, seed, folder, name="design-study")
    record = {"protocol": name, "seed": seed, "points": run.measured,
              "planned_seconds": protocols.plan(protocol).estimated_seconds,
              "recorded_seconds": run.instrument_seconds - run.warm_up_seconds,
              "warm_up_seconds": run.warm_up_seconds, "fits": {}}
    priors = {n: Uniform(*r) for n, r in PRIORS.items()}
    for fit_name, options in FITS.items():
        fit_start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = gonio.fit_recording(folder, MODEL, priors=priors, seed=seed, mcmc=False, **options)
        ls = result.least_squares
        fit: dict[str, Any] = {"redchi": ls.redchi, "jitter": result.jitter,
                               "adequate": result.adequacy.adequate if result.adequacy else None,
                               "seconds": time.perf_counter() - fit_start, "params": {}}
        for parameter, value in TRUTH.items():
            half = 1.96 * ls.stderr[parameter]
            fit["params"][parameter] = {"value": ls.values[parameter], "stderr": ls.stderr[parameter],
                                        "width": 2 * half, "in95": bool(abs(ls.values[parameter] - value) <= half)}
        record["fits"][fit_name] = fit
    shutil.rmtree(folder, ignore_errors=True)
    record["wall_seconds"] = time.perf_counter() - start
    return record



def summarise(records: list[dict[str, Any]], names: list[str]) -> list[dict[str, Any]]:
    """Per protocol: time (plan against recording), and per fit the median 95 % width, the
    coverage with its Wilson interval, the median error and reduced chi-square."""
    rows = []
    for name in names:
        mine = [r for r in records if r["protocol"] == name]
        if not mine:
            continue
        row: dict[str, Any] = {
            "protocol": name, "seeds": len(mine), "points": int(np.median([r["points"] for r in mine])),
            "planned_seconds": float(np.median([r["planned_seconds"] for r in mine])),
            "recorded_seconds": float(np.median([r["recorded_seconds"] for r in mine])),
            "time_error_max": float(max(abs(r["planned_seconds"] / r["recorded_seconds"] - 1) for r in mine)),
            "fits": {},
        }
        for fit_name in FITS:
            fits = [r["fits"][fit_name] for r in mine]
            summary: dict[str, Any] = {"redchi_median": float(np.median([f["redchi"] for f in fits])),
                                       "adequate": sum(bool(f["adequate"]) for f in fits)}
            for parameter in TRUTH:
                covered = sum(f["params"][parameter]["in95"] for f in fits)
                summary[parameter] = {
                    "width_median": float(np.median([f["params"][parameter]["width"] for f in fits])),
                    "coverage": covered / len(fits), "coverage_wilson": wilson(covered, len(fits)),
                    "error_median": float(np.median([f["params"][parameter]["value"] for f in fits])
                                          - TRUTH[parameter])}
            row["fits"][fit_name] = summary
        rows.append(row)
    return rows


def chart(rows: list[dict[str, Any]], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.8))
    for k, parameter in enumerate(TRUTH):
        ax = fig.add_subplot(1, 2, k + 1)
        for row in rows:
            designed = row["protocol"].startswith("designed")
            fit = row["fits"]["rig errors"]
            ax.plot(row["recorded_seconds"], fit[parameter]["width_median"], "o" if designed else "s",
                    color="C0" if designed else "C1")
            ax.annotate(f"{row['protocol']}\n(coverage {fit[parameter]['coverage']:.2f})",
                        (row["recorded_seconds"], fit[parameter]["width_median"]), fontsize=6,
                        xytext=(4, 2), textcoords="offset points")
        ax.set_xlabel("recorded instrument time after the lamp's warm-up [s]")
        ax.set_ylabel(f"median 95 % width of {parameter}" + (" [deg]" if parameter == "sigma" else ""))
        ax.grid(alpha=0.3)
    fig.suptitle(f"Emulated rig (default realism), sample {TRUTH_SPEC}\nfitted with {MODEL} and the rig's "
                 "errors: designed (circles), shipped (squares)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--only", action="append", default=None, metavar="PROTOCOL",
                        help="run only these protocols (by name, e.g. 'Fig 16 (shipped)'); the summary keeps "
                             "every protocol's recorded seeds")
    args = parser.parse_args()
    import gonio

    gonio.brdf(TRUTH_SPEC.split(":")[0], 45.0, 0.0, np.array([20.0]), np.array([0.0]), **TRUTH)  # compile first
    texts = protocols_studied()
    done = {(r["protocol"], r["seed"]) for r in map(json.loads, RECORDS.read_text().splitlines())} \
        if RECORDS.exists() else set()
    unknown = sorted(set(args.only or ()) - set(texts))
    if unknown:
        parser.error(f"--only {unknown}: expected one of {list(texts)}")
    todo = [(name, seed) for seed in range(args.seeds) for name in texts
            if (name, seed) not in done and (args.only is None or name in args.only)]
    print(f"{len(texts) * args.seeds} runs, {len(todo)} to do", flush=True)
    scratch = Path(tempfile.mkdtemp(prefix="gonio-design-study-"))
    start = time.perf_counter()
    try:
        for k, (name, seed) in enumerate(todo, start=1):
            record = run_one(name, texts[name], seed, scratch)
            with RECORDS.open("a") as sink:
                sink.write(json.dumps(record) + "\n")
            elapsed = time.perf_counter() - start
            fit = record["fits"]["rig errors"]["params"]["sigma"]
            print(f"[{k}/{len(todo)}] {name} seed {seed}: sigma {fit['value']:.2f} +- {fit['stderr']:.3f}, time "
                  f"{record['planned_seconds']:.0f}/{record['recorded_seconds']:.0f} s "
                  f"(eta {elapsed / k * (len(todo) - k) / 60:.1f} min)", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    records = [r for r in map(json.loads, RECORDS.read_text().splitlines()) if r["seed"] < args.seeds]
    rows = summarise(records, list(texts))
    for row in rows:
        for fit_name, fit in row["fits"].items():
            print(f"{row['protocol']:<26} {fit_name:<10} {row['seeds']:3d} seeds {row['points']:4d} points "
                  f"{row['recorded_seconds']:6.0f} s  sigma width {fit['sigma']['width_median']:.3f} "
                  f"cov {fit['sigma']['coverage']:.2f}  rho width {fit['rho']['width_median']:.4f} "
                  f"cov {fit['rho']['coverage']:.2f}  redchi {fit['redchi_median']:.2f}")
    write_json("design_study", {"model": MODEL, "truth": TRUTH_SPEC, "priors": PRIORS, "rows": rows,
                                "protocols": texts, "machine": machine()})
    chart(rows, OUT / "design_study.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Telling models apart on the emulated rig: a discrimination design against the paper's sweep.

``gonio design --discriminate lambert,oren-nayar-tabulated,pitted`` (300 s of instrument
time; over the rig's whole range, and with ``--max-angle 75``), and with ``--with-fig16``
the shipped Fig 16 protocol, are run on the default (realistic) emulated rig with
each of three truths: ``lambert`` (rho 0.8), ``oren-nayar-exact`` (sigma 30 deg, rho 0.9)
and ``pitted`` (rho 0.8, psi 45 deg, coverage 0.5), over ``--seeds`` emulator seeds. Each
recording is fitted by least squares with each candidate (the design's priors) and the
remedies for a real rig (``--calibration per-incidence --alignment all --stray-light``, as
``gonio demo``; without them a Lambertian sample measured at 80-85 deg is fitted with a
reduced chi-square of 12 by its own model), and the candidate of least BIC is chosen,
the simpler within 2 of it. Each candidate's least squares is bounded by the design's
priors (sigma 10-45 deg, psi 20-90 deg, coverage 0.2-0.8), or with ``--physical-range``
by its physical range only. Per protocol, truth, realism and range: the fraction of seeds
whose chosen model is the truth's, with a Wilson 95 % interval, and for the Lambertian
truth, oren-nayar's fitted sigma against the sample's texture slope rms (what the
sample's mesoscale slopes look like to the design: docs/design.md).

Target (docs/design.md): the right family in at least 95 % of seeds with at most a quarter
of the points of the Fig 16 and Fig 19 protocols (126 points: 31).

Run: ``python benchmarks/discrimination_study.py --seeds 20`` (about 25 minutes on one
core), the same with ``--physical-range``, and the control ``--seeds 20 --truth lambert
--realism lab:texture_slope=0 --physical-range``;
writes ``docs/benchmarks/discrimination_study.json`` (runs appended to
``discrimination_study.jsonl`` as they finish).
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

from _common import OUT, ROOT, machine, write_json
from _common import record_on_emulator, wilson

CANDIDATES = ("lambert", "oren-nayar-tabulated", "pitted")
PRIORS = {"rho": (0.5, 1.0), "sigma": (10.0, 45.0), "psi": (20.0, 90.0), "coverage": (0.2, 0.8)}
TRUTHS = {"lambert": "lambert:rho=0.8", "oren-nayar-tabulated": "oren-nayar-exact:rho=0.9,sigma=30",
          "pitted": "pitted:rho=0.8,psi=45,coverage=0.5"}
BUDGET = 300.0
RECORDS = OUT / "discrimination_study.jsonl"
#: What every fit models of the rig (with a calibration per incidence): the remedies for a
#: real rig (docs/fitting.md), as ``gonio demo``.
RIG_ERRORS = {"alignment": "all", "stray_light": True}


def protocols_studied(with_fig16: bool = False) -> dict[str, str]:
    from gonio import discrimination

    texts = {}
    for label, max_angle in (("designed to discriminate, 300 s", 90.0),
                             ("designed to discriminate, 300 s, angles to 75 deg", 75.0)):
        designed = discrimination.discriminate(list(CANDIDATES), PRIORS, BUDGET, max_angle=max_angle)
        texts[label] = discrimination.discrimination_protocol_text(designed)
    if with_fig16:
        texts["Fig 16 (shipped)"] = (ROOT / "protocols" / "oren-nayar-fig16-plaster.toml").read_text()
    return texts


def run_one(name: str, text: str, truth: str, seed: int, scratch: Path, realism: str = "lab",
            fit_range: str = "design priors") -> dict[str, Any]:
    """Measure the design on the emulated rig and choose among the candidates by BIC, each
    fitted within the design's priors (``fit_range`` "design priors") or within its
    physical range ("physical")."""
    import gonio
    import gonio.fitting
    from gonio import models, protocols
    from gonio.cli.realism import parse_realism
    from gonio.fitting.priors import Uniform

    protocol = protocols.loads(text, source=name)
    folder = scratch / f"run-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    start = time.perf_counter()
    run = record_on_emulator(protocol, TRUTHS[truth], seed, folder, reflectance=0.99, realism=realism,
                             name="discrimination")
    dataset, data_priors = gonio.load_data(folder, calibration="per-incidence")
    shutil.rmtree(folder, ignore_errors=True)
    bic, redchi, fitted = {}, {}, {}
    for model in CANDIDATES:
        names = models.get(model).param_names
        design = {n: Uniform(*r) for n, r in PRIORS.items() if n in names} if fit_range == "design priors" else {}
        priors = {**data_priors, **design}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = gonio.fitting.fit(dataset, model, priors=priors, mcmc=False, jitter=False, **RIG_ERRORS)
        ls = fit.least_squares
        bic[model] = ls.chi2 + len(fit.free) * math.log(dataset.n)
        redchi[model] = ls.redchi
        fitted[model] = {n: [ls.values[n], ls.stderr.get(n, math.nan)] for n in names if n in ls.values}
    chosen = choose_by_bic(bic)
    return {"protocol": name, "truth": truth, "seed": seed, "realism": realism, "fit_range": fit_range,
            "texture_slope": parse_realism(realism, seed).texture_slope, "points": run.measured,
            "chosen": chosen, "right": chosen == truth, "bic": bic, "redchi": redchi, "fitted": fitted,
            "wall_seconds": time.perf_counter() - start}


def choose_by_bic(bic: dict[str, float], threshold: float = 2.0) -> str:
    """The candidate of least BIC; within ``threshold`` of it, the one listed first in
    :data:`CANDIDATES` (fewest parameters first), as the comparison's BIC rule."""
    best = min(bic.values())
    return next(model for model in CANDIDATES if bic[model] <= best + threshold)


def _arm_of(record: dict[str, Any]) -> tuple[str, str]:
    """(realism, fit range) of a run; the first runs, without these fields, were on the
    ``lab`` rig with least squares bounded by the physical range only."""
    return record.get("realism", "lab"), record.get("fit_range", "physical")


def roughness_found(mine: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Of the runs whose choice was ``oren-nayar-tabulated``: its fitted sigma (median,
    range) and how often its 95 % interval (value +- 1.96 standard errors) holds the
    sample's texture slope rms, the roughness the mesoscale texture gives a Lambertian
    sample (docs/design.md, "Telling models apart")."""
    chose = [r for r in mine if r["chosen"] == "oren-nayar-tabulated" and "fitted" in r]
    if not chose:
        return None
    sigma = [r["fitted"]["oren-nayar-tabulated"]["sigma"] for r in chose]
    held = sum(abs(value - r["texture_slope"]) <= 1.96 * error for (value, error), r in zip(sigma, chose))
    values = sorted(value for value, _ in sigma)
    return {"runs": len(chose), "sigma_median": values[len(values) // 2], "sigma_range": [values[0], values[-1]],
            "texture_slope": chose[0]["texture_slope"], "interval_holds_texture_slope": held}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--with-fig16", action="store_true",
                        help="also the shipped Fig 16 protocol (its fits of pitted with the rig's errors take minutes)")
    parser.add_argument("--realism", default="lab",
                        help="the emulated rig's realism (gonio run --realism), e.g. lab:texture_slope=0")
    parser.add_argument("--physical-range", action="store_true",
                        help="fit every candidate within its physical range, not the design's priors")
    parser.add_argument("--truth", action="append", choices=list(TRUTHS),
                        help="only this truth (repeatable; default all)")
    args = parser.parse_args()
    texts = protocols_studied(args.with_fig16)
    truths = args.truth or list(TRUTHS)
    arm = (args.realism, "physical" if args.physical_range else "design priors")
    done = {(r["protocol"], r["truth"], r["seed"], _arm_of(r))
            for r in map(json.loads, RECORDS.read_text().splitlines())} if RECORDS.exists() else set()
    todo = [(name, truth, seed) for seed in range(args.seeds) for truth in truths for name in texts
            if (name, truth, seed, arm) not in done]
    print(f"{len(texts) * len(truths) * args.seeds} runs, {len(todo)} to do", flush=True)
    scratch = Path(tempfile.mkdtemp(prefix="gonio-discrimination-"))
    start = time.perf_counter()
    try:
        for k, (name, truth, seed) in enumerate(todo, start=1):
            record = run_one(name, texts[name], truth, seed, scratch, *arm)
            with RECORDS.open("a") as sink:
                sink.write(json.dumps(record) + "\n")
            elapsed = time.perf_counter() - start
            print(f"[{k}/{len(todo)}] {name}, {truth} seed {seed}: chose {record['chosen']} "
                  f"(eta {elapsed / k * (len(todo) - k) / 60:.1f} min)", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    records = [r for r in map(json.loads, RECORDS.read_text().splitlines()) if r["seed"] < args.seeds]
    rows = []
    for realism, fit_range in sorted({_arm_of(r) for r in records}):
        for name in texts:
            for truth in TRUTHS:
                mine = [r for r in records if r["protocol"] == name and r["truth"] == truth
                        and _arm_of(r) == (realism, fit_range)]
                if mine:
                    right = sum(r["right"] for r in mine)
                    rows.append({"protocol": name, "truth": truth, "realism": realism, "fit_range": fit_range,
                                 "seeds": len(mine),
                                 "points": mine[0]["points"], "right": right / len(mine),
                                 "right_wilson": wilson(right, len(mine)),
                                 "chosen": {c: sum(r["chosen"] == c for r in mine) for c in CANDIDATES},
                                 "roughness_found": roughness_found(mine) if truth == "lambert" else None})
                    print(f"{realism:<22} {fit_range:<14} {name:<34} truth {truth:<22} {mine[0]['points']:3d} points: "
                          f"right {right}/{len(mine)} chosen {rows[-1]['chosen']} {rows[-1]['roughness_found'] or ''}")
    write_json("discrimination_study", {"candidates": CANDIDATES, "priors": PRIORS, "truths": TRUTHS, "rows": rows,
                                        "protocols": texts, "machine": machine()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

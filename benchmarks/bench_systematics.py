"""What each systematic error of the rig does to the fitted sigma and rho, ignored and modelled.

The emulated rig measures the Oren & Nayar Fig 16 (plane of incidence, theta_i = 30, 45,
60 deg) and Fig 19 (off-plane, theta_i = 60 and 75 deg) protocols as shipped, each with
its diffuse reflectance standard (read at every lamp polar angle), on a sample of the
fitted model's own family (``oren-nayar``, sigma = 30 deg, rho = 0.9, ir_weight = 1), so
that what a fit gets wrong is the systematic's doing.  Each condition switches on one
systematic error of the ``lab`` preset (docs/emulator.md, "Systematic errors") with its
seeded magnitude, or all of them (``lab``), or the sample's departures (its texture, wedge,
seating and the monitor's mismatch: ``sample``, docs/emulator.md "The sample as labs meet
it"), or everything the ``lab`` preset has, the commands' default realism
(``lab_default``), or none (``ideal``); the two recordings are
reduced and joined, and ``oren-nayar`` (ir_weight fixed at 1) is fitted twice with the
relative radiance and calibration prior of ``Reduced.fit_inputs()``:

- **ignored**: nothing done about any systematic: the readings as read (no linearity
  correction), one common calibration, no rig-error parameter (the plain fit
  ``gonio fit RECORDING --no-linearity-correction``);
- **modelled**: what gonio does about it (:data:`CONDITIONS`), on the reduction's default
  readings (corrected by the camera's linearity series): the alignment parameters for zero
  offsets and sample tilt, the stray-light parameter for stray light, the linearity
  correction alone for the camera's non-linearity, the calibration per lamp polar angle
  for the beam profile, all of these for ``lab`` and ``lab_default`` (with the sample's own tilt
  too), the sample's own tilt for the sample's departures (its wedge and seat; its texture
  and the monitor's mismatch are in the reduction's budget); on the ideal rig all of them too (their
  price), the rig-error parameters alone, and the calibration per incidence alone (its
  price on a uniform beam).

The ignored fits are least squares with the Laplace (Gaussian) interval of the posterior
mode, value +- 1.96 standard errors; the modelled fits are sampled with MCMC (emcee,
gonio's convergence rule: 50 tau, R-hat < 1.01), their Laplace numbers kept beside
(``--no-mcmc``: Laplace everywhere).  Recorded per fit: value, standard error (half the
16-84 % range for MCMC), z = (value - truth) / error, whether the 95 % interval holds the
truth, reduced chi-square and the goodness-of-fit verdict, the fitted rig errors against
the truth, the seconds it took.

Writes docs/benchmarks/systematics.json and systematics.png.
Run: ``python benchmarks/bench_systematics.py`` (about half an hour on the 2-core machine);
``--seeds N`` (default 3), ``--no-mcmc``, ``--chart-only``.
"""
from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import OUT, machine, write_json  # noqa: E402

SAMPLE = "oren-nayar:sigma=30,rho=0.9,ir_weight=1"
TRUTH = {"sigma": 30.0, "rho": 0.9}
MODEL, FIXED = "oren-nayar", {"ir_weight": 1.0}
PROTOCOLS = ("oren-nayar-fig16-plaster.toml", "oren-nayar-fig19-off-plane.toml")
#: z of a two-sided 95 % interval.
Z95 = 1.959963984540054
ANGULAR = ("view_offset", "theta_i_offset", "phi_i_offset", "tilt_x", "tilt_y")
#: The sample's own tilt beyond the holder's (gonio.fitting.rig_errors.SAMPLE_TILT_NAMES).
SAMPLE_TILT_NAMES = ("sample_tilt_x", "sample_tilt_y")


@dataclass(frozen=True)
class Condition:
    """One condition: which systematics are on, and what the modelled fit does about them."""

    key: str
    label: str
    switched_on: tuple[str, ...]
    modelled: str
    alignment: tuple[str, ...] = ()
    stray_light: bool = False
    calibration: str = "common"
    short: str = ""  # the label on the chart's axis, when shorter than ``label``

    def realism(self, seed: int):
        """The rig's systematics: the lab preset of ``seed`` with only these switched on."""
        from drivers.emulator.systematics import realism

        lab = realism("lab", seed)
        return lab.only(*self.switched_on) if self.switched_on else realism("ideal", seed)

    def fit_options(self) -> dict[str, Any]:
        return {"alignment": self.alignment, "stray_light": self.stray_light}


LAB = ANGULAR + ("stray_light", "nonlinearity", "beam_falloff")
#: The sample's departures from the ideal (docs/emulator.md, "The sample as labs meet it").
SAMPLE_DEPARTURES = ("texture_albedo", "texture_slope", "wedge", "mount_tilt", "monitor_mismatch")
CONDITIONS = (
    Condition("ideal", "ideal rig", (), "every remedy (their price): the six rig-error parameters, the calibration "
              "per incidence, the linearity correction", ANGULAR, True, "per-incidence"),
    Condition("ideal_rig_errors", "ideal rig, rig-error parameters", (),
              "the six rig-error parameters alone (their price)", ANGULAR, True, short="ideal: rig errors"),
    Condition("ideal_per_incidence", "ideal rig, per-incidence calibration", (),
              "the calibration per incidence alone (its price on a uniform beam)", calibration="per-incidence",
              short="ideal: per incidence"),
    Condition("offsets", "axis zero offsets", ANGULAR[:3], "view_offset, theta_i_offset, phi_i_offset", ANGULAR[:3]),
    Condition("tilt", "holder tilt", ANGULAR[3:], "tilt_x, tilt_y", ANGULAR[3:]),
    Condition("stray", "stray light", ("stray_light",), "stray_light", stray_light=True),
    Condition("nonlinearity", "camera non-linearity", ("nonlinearity",),
              "the camera's linearity series: every reading corrected"),
    Condition("beam", "lamp beam profile", ("beam_falloff",), "calibration per lamp polar angle",
              calibration="per-incidence"),
    Condition("lab", "the rig's errors (all above)", LAB, "all of the above: alignment and stray_light parameters, "
              "the calibration per incidence, the linearity correction", ANGULAR, True, "per-incidence",
              short="rig errors (all)"),
    Condition("sample", "the sample as labs meet it", SAMPLE_DEPARTURES, "sample_tilt_x, sample_tilt_y (the "
              "sample's own tilt: its wedge, its seat, the texture's mean slope); texture and monitor mismatch in the "
              "budget", SAMPLE_TILT_NAMES, short="the sample"),
    Condition("lab_default", "lab preset (the default realism: all)", LAB + SAMPLE_DEPARTURES,
              "all of the above (the seven alignment parameters)", ANGULAR + SAMPLE_TILT_NAMES, True, "per-incidence",
              short="lab (all, the default)"),
)


# --------------------------------------------------------------------------- measuring
def measure(condition: Condition, seed: int, scratch: Path):
    """Record both protocols on one emulated rig with the condition's systematics; reduced
    with the readings as read (key False) and corrected by the linearity series (True)."""
    from gonio import acquisition, protocols
    from gonio.cli.realism import realism_metadata
    from gonio.cli.run import emulated_rig

    systematics = condition.realism(seed)
    spec = "ideal:" + ",".join(f"{k}={v!r}" for k, v in systematics.to_dict().items())
    folders = []
    with emulated_rig(SAMPLE, seed, name=f"systematics-{condition.key}-{seed}", realism=spec) as (
            rig, emulator, change_sample, metadata):
        assert metadata["rig"]["realism"] == realism_metadata(spec, systematics)
        for name in PROTOCOLS:
            protocol = protocols.load(ROOT / "protocols" / name)
            folder = scratch / f"{condition.key}-{seed}" / protocol.name
            reflectance = protocol.reference.reflectance
            acquisition.run_protocol(protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                                     change_sample=lambda which, r=reflectance, **how: change_sample(which, r, **how))
            folders.append(folder)
    reduced = {linear: acquisition.combine_reduced([acquisition.reduce_recording(f, linearity=linear)
                                                    for f in folders]) for linear in (False, True)}
    shutil.rmtree(scratch / f"{condition.key}-{seed}", ignore_errors=True)
    return reduced, systematics


# --------------------------------------------------------------------------- fitting
def summarise(result, systematics, seconds: float) -> dict[str, Any]:
    """The numbers of one fit against the truth (module docstring)."""
    ls = result.least_squares
    post = result.posterior
    out: dict[str, Any] = {"method": "mcmc" if post else "laplace", "seconds": seconds, "redchi": ls.redchi,
                           "chi2_p": result.adequacy.chi2_p, "adequate": bool(result.adequacy.adequate),
                           "n_data": result.dataset.n, "quantity": result.dataset.quantity, "free": list(result.free),
                           "params": {}, "rig_errors": {}}
    truth = dict(TRUTH, **systematics.to_dict())
    for name in result.free:
        if name not in truth:
            continue
        if post:
            value, low, high = post["median"][name], post["p2_5"][name], post["p97_5"][name]
            error = 0.5 * (post["p84"][name] - post["p16"][name])
        else:
            value, error = ls.values[name], ls.stderr[name]
            low, high = value - Z95 * error, value + Z95 * error
        row = {"value": value, "error": error, "low95": low, "high95": high, "truth": truth[name],
               "z": (value - truth[name]) / error if error > 0 else math.nan,
               "inside95": bool(low <= truth[name] <= high)}
        out["params" if name in TRUTH else "rig_errors"][name] = row
    if post:
        out["converged"] = bool(result.converged)
        out["mcmc_steps"] = int(result.mcmc.n_steps)
        out["laplace"] = {name: {"value": ls.values[name], "error": ls.stderr[name],
                                 "low95": ls.values[name] - Z95 * ls.stderr[name],
                                 "high95": ls.values[name] + Z95 * ls.stderr[name]} for name in result.free}
    return out


def fit_both(condition: Condition, reduced, systematics, seed: int, mcmc: bool):
    """The ignored and the modelled fit of one recording (module docstring)."""
    from gonio.fitting import ConvergenceWarning, fit

    out = {}
    arms = (("ignored", *reduced[False].fit_inputs(), {}, False),
            ("modelled", *reduced[True].fit_inputs(condition.calibration), condition.fit_options(), mcmc))
    for arm, data, priors, options, sample in arms:
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # recorded: "converged"
            result = fit(data, MODEL, FIXED, priors=priors, mcmc=sample, seed=seed, **options)
        out[arm] = summarise(result, systematics, time.perf_counter() - start)
        out[arm]["calibration"] = data.metadata.get("calibration", "common")
    return out


# --------------------------------------------------------------------------- summary
def coverage(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Per condition, arm and parameter: the truth inside the 95 % interval (k of n), and z."""
    table: dict[str, Any] = {}
    for condition in CONDITIONS:
        runs = [r for r in records if r["condition"] == condition.key]
        table[condition.key] = {}
        for arm in ("ignored", "modelled"):
            table[condition.key][arm] = {}
            for name in TRUTH:
                rows = [r[arm]["params"][name] for r in runs if name in r[arm]["params"]]
                table[condition.key][arm][name] = {
                    "inside95": sum(row["inside95"] for row in rows), "n": len(rows),
                    "z": [row["z"] for row in rows], "bias": [row["value"] - row["truth"] for row in rows],
                    "adequate": sum(r[arm]["adequate"] for r in runs)}
    return table


def chart(records: list[dict[str, Any]], path: Path) -> None:
    """Per condition, ignored and modelled: z of sigma and rho with the 95 % band (top), and
    their standard errors relative to the ideal rig's plain fit of the same seed (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    figure = Figure(figsize=(11, 7.2))
    axes = figure.subplots(2, 2, sharex=True)
    keys = [c.key for c in CONDITIONS]
    reference = {(r["seed"], name): r["ignored"]["params"][name]["error"]
                 for r in records if r["condition"] == "ideal" for name in TRUTH}
    for column, name in enumerate(TRUTH):
        top, bottom = axes[0, column], axes[1, column]
        for offset, arm, colour in ((-0.15, "ignored", "tab:red"), (0.15, "modelled", "tab:blue")):
            for k, key in enumerate(keys):
                rows = [(r["seed"], r[arm]["params"][name]) for r in records
                        if r["condition"] == key and name in r[arm]["params"]]
                x = np.full(len(rows), k + offset)
                top.plot(x, [row["z"] for _, row in rows], "o", color=colour, ms=5, alpha=0.8,
                         label=arm if k == 0 else None)
                ratio = [row["error"] / reference[(seed, name)] for seed, row in rows if (seed, name) in reference]
                bottom.plot(x[:len(ratio)], ratio, "o", color=colour, ms=5, alpha=0.8)
        top.axhspan(-Z95, Z95, color="0.85", zorder=0, label="the 95 % interval holds the truth")
        top.set_yscale("symlog", linthresh=2.0)
        top.set_title(f"{name}: (fitted - truth) / standard error")
        bottom.set_yscale("log")
        bottom.axhline(1.0, color="0.5", lw=0.8)
        bottom.set_title(f"{name}: standard error / the ideal rig's plain fit")
        bottom.set_xticks(range(len(keys)), [c.short or c.label for c in CONDITIONS], rotation=30, ha="right")
        for ax in (top, bottom):
            ax.grid(axis="y", alpha=0.3)
    axes[0, 0].set_ylabel("z (symmetric log scale)")
    axes[1, 0].set_ylabel("error ratio")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="upper center", ncol=3, fontsize=9, frameon=False)
    figure.subplots_adjust(left=0.08, right=0.99, bottom=0.17, top=0.9, wspace=0.18, hspace=0.2)
    figure.savefig(path, dpi=110)


# --------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="emulator seeds per condition (default 3)")
    parser.add_argument("--no-mcmc", action="store_true", help="no MCMC at all (Laplace intervals only)")
    parser.add_argument("--chart-only", action="store_true", help="redraw the chart from the JSON of the last run")
    args = parser.parse_args(argv)
    if args.chart_only:
        import json

        chart(json.loads((OUT / "systematics.json").read_text())["records"], OUT / "systematics.png")
        return 0
    warnings.simplefilter("ignore", RuntimeWarning)
    began, cpu_began, load_before = time.perf_counter(), time.process_time(), os.getloadavg()[0]
    scratch = Path(tempfile.mkdtemp(prefix="gonio-systematics-"))
    records: list[dict[str, Any]] = []
    try:
        for condition in CONDITIONS:
            for seed in range(args.seeds):
                start = time.perf_counter()
                reduced, systematics = measure(condition, seed, scratch)
                fits = fit_both(condition, reduced, systematics, seed, not args.no_mcmc)
                records.append({"condition": condition.key, "seed": seed, "systematics": systematics.to_dict(),
                                **fits, "seconds": time.perf_counter() - start})
                line = ", ".join(f"{arm} sigma z={fits[arm]['params']['sigma']['z']:+.2g}" for arm in fits
                                 if "sigma" in fits[arm]["params"])
                print(f"{condition.key:<20} seed {seed}: {line} ({time.perf_counter() - start:.0f} s, modelled "
                      f"{fits['modelled']['seconds']:.0f} s)", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    OUT.mkdir(parents=True, exist_ok=True)
    chart(records, OUT / "systematics.png")
    payload = {
        "benchmark": "bench_systematics", "command": "python benchmarks/" + Path(__file__).name + " "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "sample": SAMPLE, "fitted_model": MODEL, "fixed": FIXED, "truth": TRUTH, "protocols": list(PROTOCOLS),
        "seeds": args.seeds,
        "conditions": [{"key": c.key, "label": c.label, "switched_on": list(c.switched_on), "modelled": c.modelled}
                       for c in CONDITIONS],
        "coverage": coverage(records), "records": records,
        "fit_seconds": {arm: {c.key: [r[arm]["seconds"] for r in records if r["condition"] == c.key]
                              for c in CONDITIONS} for arm in ("ignored", "modelled")},
        "wall_seconds": time.perf_counter() - began, "cpu_seconds": time.process_time() - cpu_began,
        "load_average_before_after": [load_before, os.getloadavg()[0]], "machine": machine(),
    }
    path = write_json("systematics", payload)
    print(f"wrote {path} and {OUT / 'systematics.png'} ({payload['wall_seconds']:.0f} s wall, "
          f"{payload['cpu_seconds']:.0f} s CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Stated uncertainty against observed scatter on the emulated rig.

The reduction (:func:`gonio.reduction.reduce_recording`) states an uncertainty budget for
every radiance reading. This benchmark measures whether that budget describes the scatter
it claims to, on the emulated wall plaster (``oren-nayar``, sigma = 30 deg, rho = 0.9,
interreflection weight 1), in two ways:

1. **Repeats.** Three geometries are measured ``REPEATS`` times each: bright
   (theta_i = 30, view = -20 deg), dim (theta_i = 60, view = -80 deg) and grazing
   (theta_i = 85, view = 30 deg), all in the plane of incidence. For each geometry the
   ratio of the observed standard deviation of one reading (after the reduction moves
   each reading to the group's mean readback geometry) to the stated one (the part of
   the per-reading budget that varies between repeats) is reported, from
   ``Reduced.repeat_statistics``. With ``n`` readings the ratio has a sampling error of
   about ``1 / sqrt(2 (n - 1))`` (4 % for 300). Three rig configurations:

   - ``monitor``: the default rig, the lamp divided out by its monitor (``lamp="monitor"``);
   - ``checks``: no lamp monitor; the protocol re-measures a check geometry
     (``[checks]`` every 10 points, 5 frames, at [45, 0, -10]) and the reduction
     interpolates the drift and measures the flicker from it (``lamp="checks"``);
   - ``steady``: no lamp monitor, flicker and drift switched off in the emulated lamp, no
     checks, and a CCD-only budget (``lamp="none"``).

   Target: every ratio within 0.85 to 1.15.

2. **Reduced chi-square of the true model.** The shipped Fig 16 protocol
   (protocols/oren-nayar-fig16-plaster.toml, with its reference standard) is measured for
   ``CHI2_SEEDS`` emulator seeds in the ``monitor`` and ``checks`` configurations (the
   latter with the same ``[checks]`` table added), reduced, and fitted by least squares
   with the true model (``oren-nayar``, ``ir_weight`` fixed at 1, the calibration prior of
   ``Reduced.fit_inputs``, no extra-noise term). Target: median reduced chi-square within
   0.8 to 1.25. The fitted rho and sigma and their standard errors are recorded per seed,
   and the fitted scale against the calibration prior (its pull, in units of the prior's
   width: a pull far beyond a few units means the least-squares fit was not held by the
   prior).

Writes docs/benchmarks/uncertainty.json and docs/benchmarks/uncertainty.png; the script
exits 0 whether or not the targets are met (the JSON and the printed table say which).
Run: ``python benchmarks/bench_uncertainty.py``.
"""
from __future__ import annotations

import math
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.emulator.lamp import LampParams
from gonio import acquisition, protocols
from gonio.cli.run import emulated_rig
from gonio.fitting import fit
from gonio.reduction import CHECK_BLOCK, Reduced, read_readings, reduce_recording

sys.path.insert(0, str(ROOT / "benchmarks"))
from _common import OUT, machine, write_json

#: The emulated sample (the true model of the chi-square study).
SAMPLE = "oren-nayar:sigma=30,rho=0.9"
#: True values of the fitted model parameters.
TRUTH = {"rho": 0.9, "sigma": 30.0}
#: Albedo of the emulated reference standard (the Fig 16 protocol's certificate).
REFERENCE_REFLECTANCE = 0.99
#: Readings per repeated geometry.
REPEATS = 300
#: Repeated geometries: name, theta_i [deg], phi_i [deg], signed view [deg].
GEOMETRIES = (("bright", 30.0, 0.0, -20.0), ("dim", 60.0, 0.0, -80.0), ("grazing", 85.0, 0.0, 30.0))
#: Emulator seeds of the chi-square study.
CHI2_SEEDS = tuple(range(10))
#: Target band of observed / stated standard deviation.
RATIO_TARGET = (0.85, 1.15)
#: Target band of the median reduced chi-square.
REDCHI_TARGET = (0.8, 1.25)
#: The lamp-check table added to protocols measured without a lamp monitor.
CHECKS_TABLE = "\n[checks]\nevery = 10\nframes = 5\ngeometry = [45, 0, -10]\n"
#: The shipped protocol of the chi-square study.
FIG16 = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"


@dataclass(frozen=True)
class Configuration:
    """A rig configuration and the way its reduction handles the lamp.

    Attributes
    ----------
    key : str
        Short name used in the JSON.
    label : str
        Human-readable description.
    lamp : str
        ``lamp`` argument of :func:`gonio.reduction.reduce_recording`.
    checks : bool
        Add :data:`CHECKS_TABLE` to the protocols.
    seed : int
        Emulator seed of the repeat study.
    options : mapping
        Keyword arguments of :class:`drivers.emulator.rig.EmulatedRig`.
    """

    key: str
    label: str
    lamp: str
    checks: bool
    seed: int
    options: Mapping[str, Any] = field(default_factory=dict)

    def describe(self) -> dict[str, Any]:
        """JSON-able description of the configuration."""
        return {"key": self.key, "label": self.label, "lamp": self.lamp, "checks": CHECKS_TABLE.strip() if self.checks
                else None, "repeat_seed": self.seed,
                "emulator_options": {k: (v if isinstance(v, (bool, int, float, str)) else repr(v))
                                     for k, v in self.options.items()}}


CONFIGURATIONS = (
    Configuration("monitor", "with monitor", "monitor", False, 101),
    Configuration("checks", "without monitor, lamp checks", "checks", True, 102, {"monitor": False}),
    Configuration("steady", "flicker and drift off (CCD-only budget)", "none", False, 103,
                  {"monitor": False, "lamp_params": LampParams(flicker_rms=0.0, drift_amplitude=0.0)}),
)
#: Configurations of the chi-square study.
CHI2_CONFIGURATIONS = ("monitor", "checks")


# --------------------------------------------------------------------------- measuring
def repeats_protocol(repeats: int, checks: bool) -> str:
    """Protocol text measuring each of :data:`GEOMETRIES` ``repeats`` times.

    Parameters
    ----------
    repeats : int
        Readings per geometry.
    checks : bool
        Add the lamp-check table.

    Returns
    -------
    str
        TOML protocol text.
    """
    blocks = "".join(
        f"\n[[block]]\nname = \"{name}\"\ntheta_i = {ti}\nphi_i = {pi}\nview = [{view}]\nrepeats = {repeats}\n"
        for name, ti, pi, view in GEOMETRIES)
    text = ("[protocol]\nname = \"uncertainty-repeats\"\n"
            "description = \"Repeated readings at a bright, a dim and a grazing geometry\"\n\n"
            "[sample]\nlabel = \"wall plaster (sample A)\"\n\n"
            "[exposure]\nmode = \"auto\"\ntime = 0.02\n\n"
            "[darks]\nat_start = true\nevery = 20\n" + blocks)
    return text + (CHECKS_TABLE if checks else "")


def measure(text: str, configuration: Configuration, seed: int, folder: Path) -> float:
    """Run a protocol on an emulated rig into ``folder``.

    Parameters
    ----------
    text : str
        Protocol text.
    configuration : Configuration
        Rig configuration (emulator options).
    seed : int
        Emulator seed.
    folder : Path
        Recording folder (created).

    Returns
    -------
    float
        Wall time of the run [s].
    """
    protocol = protocols.loads(text)
    start = time.perf_counter()
    name = f"bench-uncertainty-{configuration.key}-{seed}-{folder.name}"
    with emulated_rig(SAMPLE, seed, name=name, **configuration.options) as (rig, emulator, change_sample, metadata):
        acquisition.run_protocol(protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                                 change_sample=lambda which: change_sample(which, REFERENCE_REFLECTANCE))
    return time.perf_counter() - start


# --------------------------------------------------------------------------- repeats
def nearest_statistics(reduced: Reduced, theta_i: float, phi_i: float, view: float) -> dict[str, Any]:
    """The repeat statistics of the geometry read back closest to a planned one."""
    planned = np.array([theta_i, phi_i, view])
    distances = [float(np.max(np.abs(np.array(s["geometry"]) - planned))) for s in reduced.repeat_statistics]
    return reduced.repeat_statistics[int(np.argmin(distances))]


def nearest_value(reduced: Reduced, geometry: Sequence[float]) -> float:
    """The reduced radiance at a readback geometry (theta_i, phi_i, view)."""
    here = np.stack([reduced.theta_i, reduced.phi_i, reduced.view], axis=1)
    return float(reduced.radiance[int(np.argmin(np.max(np.abs(here - np.asarray(geometry)), axis=1)))])


def reading_budget(folder: Path, lamp: str, theta_i: float, view: float) -> dict[str, float]:
    """Median relative size of each per-reading budget component at one planned geometry.

    Parameters
    ----------
    folder : Path
        Recording folder.
    lamp : str
        Lamp handling of the reduction.
    theta_i, view : float
        Planned lamp polar angle and signed camera angle [deg].

    Returns
    -------
    dict of str to float
        Component name -> median over the readings of component / value [-] (before the
        reduction takes out the part common to the repeats, e.g. PRNU of one window).
    """
    readings = read_readings(folder, lamp)
    rows = readings.index[(np.abs(readings.column("theta_i") - theta_i) < 1e-6)
                          & (np.abs(readings.column("view") - view) < 1e-6)
                          & (readings.column("block") != CHECK_BLOCK)]
    value = np.abs(readings.value[rows])
    return {name: float(np.median(c[rows] / value)) for name, c in readings.budget.items()}


def geometry_record(reduced: Reduced, folder: Path, lamp: str, geometry: tuple) -> dict[str, Any]:
    """Observed and stated scatter of one repeated geometry.

    Parameters
    ----------
    reduced : Reduced
        The reduced recording.
    folder : Path
        Its folder (for the per-reading budget).
    lamp : str
        Lamp handling of the reduction.
    geometry : tuple
        ``(name, theta_i, phi_i, view)`` as in :data:`GEOMETRIES`.

    Returns
    -------
    dict
        Geometry, ``n``, both standard deviations (absolute and relative to the value),
        their ratio with its sampling error, the chi-square and the per-reading budget.
    """
    name, theta_i, phi_i, view = geometry
    stats = nearest_statistics(reduced, theta_i, phi_i, view)
    value = nearest_value(reduced, stats["geometry"])
    ratio = stats["observed_std"] / stats["stated_std"]
    n = int(stats["n"])
    return {
        "geometry": name, "planned": [theta_i, phi_i, view], "readback_mean": stats["geometry"], "n": n,
        "value": value, "observed_std": stats["observed_std"], "stated_std": stats["stated_std"],
        "observed_relative": stats["observed_std"] / abs(value), "stated_relative": stats["stated_std"] / abs(value),
        "ratio": ratio, "ratio_sampling_error": ratio / math.sqrt(2.0 * (n - 1)),
        "reduced_chi2": stats["chi2"] / (n - 1),
        "within_target": RATIO_TARGET[0] <= ratio <= RATIO_TARGET[1],
        "reading_budget_median_relative": reading_budget(folder, lamp, theta_i, view),
    }


def repeat_study(configuration: Configuration, repeats: int) -> dict[str, Any]:
    """Measure and reduce the repeat protocol in one configuration.

    Parameters
    ----------
    configuration : Configuration
        Rig configuration and lamp handling.
    repeats : int
        Readings per geometry.

    Returns
    -------
    dict
        The configuration, one record per geometry (:func:`geometry_record`), the
        reduction's consistency checks and budget summary, and the wall times.
    """
    with tempfile.TemporaryDirectory(prefix="gonio-bench-uncertainty-") as tmp:
        folder = Path(tmp) / "repeats"
        measure_wall = measure(repeats_protocol(repeats, configuration.checks), configuration, configuration.seed,
                               folder)
        start = time.perf_counter()
        reduced = reduce_recording(folder, lamp=configuration.lamp)
        geometries = [geometry_record(reduced, folder, configuration.lamp, g) for g in GEOMETRIES]
        reduce_wall = time.perf_counter() - start
    return {"configuration": configuration.describe(), "seed": configuration.seed, "repeats": repeats,
            "geometries": geometries, "consistency": dict(reduced.consistency),
            "budget_summary": reduced.budget_summary(), "measure_wall_s": measure_wall, "reduce_wall_s": reduce_wall,
            "all_within_target": all(g["within_target"] for g in geometries)}


# --------------------------------------------------------------------------- chi-square
def fit_seed(configuration: Configuration, seed: int, text: str, tmp: Path) -> dict[str, Any]:
    """Measure the Fig 16 protocol with one seed and fit the true model to it.

    Parameters
    ----------
    configuration : Configuration
        Rig configuration and lamp handling.
    seed : int
        Emulator seed.
    text : str
        Protocol text (with checks where the configuration has them).
    tmp : Path
        Folder for the recording.

    Returns
    -------
    dict
        Seed, reduced chi-square and its degrees of freedom, the fitted rho and sigma with
        their standard errors and normalised errors, the fitted scale against the
        calibration prior (:func:`calibration_pull`), the reduction's consistency checks.
    """
    folder = tmp / f"fig16-{configuration.key}-{seed}"
    measure(text, configuration, seed, folder)
    reduced = reduce_recording(folder, lamp=configuration.lamp)
    dataset, priors = reduced.fit_inputs()
    result = fit(dataset, "oren-nayar", fixed={"ir_weight": 1.0}, priors=priors, mcmc=False).least_squares
    out: dict[str, Any] = {"seed": seed, "redchi": result.redchi, "dof": result.dof, "n_data": len(dataset.value)}
    for name, truth in TRUTH.items():
        value, error = result.values[name], result.stderr[name]
        out[name] = value
        out[f"{name}_stderr"] = error
        out[f"{name}_normalised_error"] = (value - truth) / error
    out.update(calibration_pull(reduced, result.values["scale"], result.stderr["scale"]))
    out["consistency"] = dict(reduced.consistency)
    return out


def calibration_pull(reduced: Reduced, scale: float, scale_stderr: float) -> dict[str, float]:
    """The fitted ``scale`` against the calibration prior from the reference standard.

    Parameters
    ----------
    reduced : Reduced
        The reduced recording (its reference irradiance E_0 and uncertainty).
    scale, scale_stderr : float
        Fitted scale and its standard error [radiance unit].

    Returns
    -------
    dict
        The scale, its standard error, E_0 and its uncertainty, the relative difference
        ``scale / E_0 - 1`` and the pull ``(scale - E_0) / u(E_0)``: a pull far beyond a
        few units means the prior did not constrain the least-squares scale.
    """
    e0, u0 = reduced.reference_irradiance, reduced.reference_irradiance_sigma
    return {"scale": scale, "scale_stderr": scale_stderr, "reference_irradiance": e0,
            "reference_irradiance_sigma": u0, "scale_relative_to_reference": scale / e0 - 1.0,
            "scale_pull": (scale - e0) / u0}


def chi_square_study(configuration: Configuration, seeds: Sequence[int]) -> dict[str, Any]:
    """Reduced chi-square of the true model on the Fig 16 sweep over several seeds.

    Parameters
    ----------
    configuration : Configuration
        Rig configuration and lamp handling.
    seeds : sequence of int
        Emulator seeds.

    Returns
    -------
    dict
        Per-seed records (:func:`fit_seed`), the median reduced chi-square, whether it
        is within :data:`REDCHI_TARGET`, and the rms normalised errors of rho and sigma.
    """
    text = FIG16.read_text() + (CHECKS_TABLE if configuration.checks else "")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gonio-bench-uncertainty-") as tmp:
        per_seed = [fit_seed(configuration, seed, text, Path(tmp)) for seed in seeds]
    median = float(np.median([r["redchi"] for r in per_seed]))
    rms = {name: float(np.sqrt(np.mean([r[f"{name}_normalised_error"] ** 2 for r in per_seed]))) for name in TRUTH}
    return {"configuration": configuration.describe(), "protocol": str(FIG16.relative_to(ROOT)),
            "per_seed": per_seed, "median_redchi": median,
            "within_target": REDCHI_TARGET[0] <= median <= REDCHI_TARGET[1],
            "rms_normalised_error": rms,
            "median_abs_scale_pull": float(np.median([abs(r["scale_pull"]) for r in per_seed])),
            "wall_s": time.perf_counter() - start}


# --------------------------------------------------------------------------- output
def chart(payload: Mapping[str, Any], path: Path) -> None:
    """Two panels: ratio per geometry per configuration; reduced chi-square per seed.

    Parameters
    ----------
    payload : mapping
        The benchmark's JSON payload.
    path : Path
        PNG file to write.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 4.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    studies = payload["repeats"]
    width = 0.8 / len(studies)
    for k, study in enumerate(studies):
        x = np.arange(len(study["geometries"])) + (k - (len(studies) - 1) / 2) * width
        ratios = [g["ratio"] for g in study["geometries"]]
        errors = [g["ratio_sampling_error"] for g in study["geometries"]]
        left.errorbar(x, ratios, yerr=errors, fmt="o", color=f"C{k}", capsize=3, label=study["configuration"]["label"])
    left.axhspan(*RATIO_TARGET, color="C2", alpha=0.15, label=f"target {RATIO_TARGET[0]}-{RATIO_TARGET[1]}")
    left.axhline(1.0, color="k", lw=0.8)
    left.set_xticks(range(len(GEOMETRIES)), [f"{n}\n({ti:g}, {pi:g}, {v:g})" for n, ti, pi, v in GEOMETRIES])
    left.set_ylabel("observed / stated standard deviation")
    left.set_title(f"Repeats ({payload['repeats'][0]['repeats']} per geometry; bars: sampling error)", fontsize=10)
    left.legend(fontsize=8)
    for k, study in enumerate(payload["chi_square"]):
        seeds = [r["seed"] for r in study["per_seed"]]
        color = f"C{[c.key for c in CONFIGURATIONS].index(study['configuration']['key'])}"
        right.plot(seeds, [r["redchi"] for r in study["per_seed"]], "o", color=color,
                   label=f"{study['configuration']['label']} (median {study['median_redchi']:.2f})")
        right.axhline(study["median_redchi"], color=color, ls="--", lw=1.0)
    right.axhspan(*REDCHI_TARGET, color="C2", alpha=0.15, label=f"target median {REDCHI_TARGET[0]}-{REDCHI_TARGET[1]}")
    right.axhline(1.0, color="k", lw=0.8)
    right.set_xticks(list(CHI2_SEEDS))
    right.set_xlabel("emulator seed")
    right.set_ylabel("reduced chi-square of the true model")
    right.set_title("Fig 16 sweep, oren-nayar least squares, no extra noise", fontsize=10)
    right.legend(fontsize=8)
    for ax in (left, right):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=110)


def print_table(payload: Mapping[str, Any]) -> None:
    """Print the ratios, the chi-square medians and which targets are met."""
    print(f"{'configuration':<42}{'geometry':<10}{'n':>5}{'observed':>11}{'stated':>11}{'ratio':>8}{'+-':>7}  target")
    for study in payload["repeats"]:
        for g in study["geometries"]:
            print(f"{study['configuration']['label']:<42}{g['geometry']:<10}{g['n']:>5}{g['observed_relative']:>11.2e}"
                  f"{g['stated_relative']:>11.2e}{g['ratio']:>8.3f}{g['ratio_sampling_error']:>7.3f}  "
                  f"{'met' if g['within_target'] else 'MISSED'}")
    print(f"\n{'configuration':<42}{'median redchi':>14}  per seed")
    for study in payload["chi_square"]:
        values = " ".join(f"{r['redchi']:.2f}" for r in study["per_seed"])
        print(f"{study['configuration']['label']:<42}{study['median_redchi']:>14.3f}  {values}  "
              f"{'met' if study['within_target'] else 'MISSED'}")
        rms = ", ".join(f"{name} {value:.2f}" for name, value in study["rms_normalised_error"].items())
        print(f"{'':<42}{'':>14}  rms normalised error: {rms}; "
              f"median |scale - E_0| / u(E_0) = {study['median_abs_scale_pull']:.3g}")
    print()
    for name, met in payload["targets_met"].items():
        print(f"target {name}: {'met' if met else 'MISSED'}")
    print(f"wall time {payload['wall_s']:.0f} s")


def main() -> int:
    """Run both studies, write the JSON and the chart, print the table; always 0."""
    start = time.perf_counter()
    repeats = [repeat_study(c, REPEATS) for c in CONFIGURATIONS]
    by_key = {c.key: c for c in CONFIGURATIONS}
    chi_square = [chi_square_study(by_key[key], CHI2_SEEDS) for key in CHI2_CONFIGURATIONS]
    targets_met = {f"ratio ({s['configuration']['key']})": s["all_within_target"] for s in repeats}
    targets_met.update({f"median redchi ({s['configuration']['key']})": s["within_target"] for s in chi_square})
    payload = {
        "benchmark": "uncertainty",
        "command": "python benchmarks/bench_uncertainty.py",
        "machine": machine(),
        "sample": SAMPLE,
        "targets": {"ratio": list(RATIO_TARGET), "median_redchi": list(REDCHI_TARGET),
                    "ratio_definition": "observed std of one reading / stated std (the varying part of its budget)",
                    "redchi_definition": "result.least_squares.redchi of gonio.fitting.fit(dataset, 'oren-nayar', "
                                         "fixed={'ir_weight': 1.0}, priors=priors, mcmc=False) with dataset, priors "
                                         "= Reduced.fit_inputs() on the Fig 16 sweep; no extra-noise term"},
        "repeats": repeats,
        "chi_square": chi_square,
        "targets_met": targets_met,
        "all_targets_met": all(targets_met.values()),
        "wall_s": time.perf_counter() - start,
    }
    write_json("uncertainty", payload)
    chart(payload, OUT / "uncertainty.png")
    print_table(payload)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Stated uncertainty against observed scatter on the emulated rig.

The reduction (:func:`gonio.reduction.reduce_recording`) states an uncertainty budget for
every radiance reading. This benchmark measures whether that budget describes the scatter
it claims to, on the emulated wall plaster (``oren-nayar``, sigma = 30 deg, rho = 0.9,
interreflection weight 1). Two parts:

**A real lab's rig** (the default realism, ``lab``: misalignment, stray light,
non-linearity, beam profile, the sample's texture and wedge, remounting, a monitor that
does not see the sample's beam exactly; docs/emulator.md):

A1. **Remountings.** The bright, dim and grazing geometries below are measured in
    :data:`REMOUNTS` mountings of the sample (two readings each). The reduction of every
    group of :data:`GROUP` consecutive mountings (what a user measures) states the
    ``mounting`` component; the standard deviation of one mounting's value it implies
    (with the readings' own noise) is compared with the scatter of the values of the
    mountings outside the group: ``sqrt(mean observed^2 / mean stated^2)`` over the groups.
    Target: within 0.85 to 1.15 at each geometry.
A2. **Reduced chi-square with mountings.** The Fig 16 protocol with
    ``[sample] mountings = 4`` over ``CHI2_SEEDS`` seeds, fitted by least squares with the
    true model and the rig's errors as parameters (``alignment="all"``,
    ``stray_light=True``, the calibration per incidence), the full covariance, no
    extra-noise term. Target: median within 0.8 to 1.25.
A3. **Texture.** For :data:`TEXTURE_SEEDS` samples (seeds), the offset of the window's
    mean from the untextured sample (the emulator's ground truth) against the ``texture``
    component the reduction states from one image: the rms of their ratio (1 when the
    statement is right; its sampling error ``1 / sqrt(2 n)``).
A4. **Median stated uncertainty** of the Fig 16 sweep as shipped (one mounting). Target:
    between 0.1 % and 3 % (real gonioreflectometers: 0.075-0.3 % standard uncertainty at
    NIST's STARR, 2.6-3.6 % in the CUReT data).

**The idealised rig** (``--realism ideal``, the figures the reduction was first
validated with):

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

   Target: every ratio within 0.85 to 1.15, or (the lab rig) within two of its combined
   sampling errors of 1: there the stated deviation rests mostly on the monitor series'
   Type A estimate (47 degrees of freedom in one mounting: 10 % of itself).

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
Run: ``python benchmarks/bench_uncertainty.py`` (``--lab-only`` for part A).
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
from gonio.reduction import CHECK_BLOCK, REFERENCE_BLOCK, Reduced, read_readings, reduce_recording

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
#: Mountings of the remount study (A1), the size of a user's group of them, the readings
#: per mounting and geometry, and the mountings of the chi-square study (A2).
REMOUNTS, GROUP, REMOUNT_READINGS, CHI2_MOUNTINGS = 40, 4, 2, 4
#: Samples of the texture study (A3).
TEXTURE_SEEDS = tuple(range(100))
#: Target band of the median stated relative uncertainty of the shipped Fig 16 sweep (A4).
STATED_TARGET = (1e-3, 3e-2)
#: Components every mounting's readings of a geometry share (not in the scatter between
#: mountings; gonio.reduction.combining.COMMON_TO_MOUNTINGS).
COMMON = ("prnu", "texture", "linearity", "mounting")


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
    realism: str = "ideal"

    def describe(self) -> dict[str, Any]:
        """JSON-able description of the configuration."""
        return {"key": self.key, "label": self.label, "lamp": self.lamp, "checks": CHECKS_TABLE.strip() if self.checks
                else None, "repeat_seed": self.seed, "realism": self.realism,
                "emulator_options": {k: (v if isinstance(v, (bool, int, float, str)) else repr(v))
                                     for k, v in self.options.items()}}


CONFIGURATIONS = (
    Configuration("lab", "lab rig (default), with monitor", "monitor", False, 104, realism="lab"),
    Configuration("monitor", "ideal rig, with monitor", "monitor", False, 101),
    Configuration("checks", "ideal rig, without monitor, lamp checks", "checks", True, 102, {"monitor": False}),
    Configuration("steady", "ideal rig, flicker and drift off (CCD-only budget)", "none", False, 103,
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
    with emulated_rig(SAMPLE, seed, name=name, realism=configuration.realism,
                      **configuration.options) as (rig, emulator, change_sample, metadata):
        acquisition.run_protocol(protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                                 change_sample=lambda which, **how: change_sample(which, REFERENCE_REFLECTANCE, **how))
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
    budget = reading_budget(folder, lamp, theta_i, view)
    statement = _statement_error(reduced, budget, stats["stated_std"] / abs(value))
    combined = ratio * math.sqrt(1.0 / (2.0 * (n - 1)) + statement**2)
    return {
        "geometry": name, "planned": [theta_i, phi_i, view], "readback_mean": stats["geometry"], "n": n,
        "value": value, "observed_std": stats["observed_std"], "stated_std": stats["stated_std"],
        "observed_relative": stats["observed_std"] / abs(value), "stated_relative": stats["stated_std"] / abs(value),
        "ratio": ratio, "ratio_sampling_error": ratio / math.sqrt(2.0 * (n - 1)),
        "reduced_chi2": stats["chi2"] / (n - 1),
        "statement_sampling_error": statement, "combined_sampling_error": combined,
        "within_target": RATIO_TARGET[0] <= ratio <= RATIO_TARGET[1] or abs(ratio - 1.0) <= 2.0 * combined,
        "reading_budget_median_relative": budget,
    }


def _statement_error(reduced: Reduced, budget: Mapping[str, float], stated_relative: float) -> float:
    """Relative sampling error of a stated standard deviation from the Type A estimate of the
    lamp monitor's ratio in it (its degrees of freedom in the reduction's consistency
    checks; 0 where the budget has none): the estimate's ``1 / sqrt(2 dof)`` times that
    term's share of the stated variance."""
    dof = reduced.consistency.get("monitor_ratio_dof")
    ratio = budget.get("monitor_ratio", 0.0)
    if not dof or not ratio or not stated_relative:
        return 0.0
    return (ratio / stated_relative) ** 2 / math.sqrt(2.0 * dof)


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


# --------------------------------------------------------------------------- A: a real lab's rig
def _with_sample_fields(text: str, fields: str) -> str:
    """Protocol text with ``fields`` (TOML lines) added to its [sample] table."""
    return text.replace("[sample]\n", "[sample]\n" + fields + "\n", 1)


def remount_protocol() -> str:
    """The bright, dim and grazing geometries, :data:`REMOUNT_READINGS` readings each, in
    :data:`REMOUNTS` mountings."""
    return _with_sample_fields(repeats_protocol(REMOUNT_READINGS, False), f"mountings = {REMOUNTS}")


def _subrecording(folder: Path, mountings: Sequence[int], out: Path) -> Path:
    """A copy of a recording holding only the rows (and the metadata) of some mountings:
    what a user who measured only those would have."""
    import csv
    import json
    import shutil

    out.mkdir(parents=True)
    meta = json.loads((folder / "metadata.json").read_text())
    meta["mountings"] = {k: v for k, v in meta.get("mountings", {}).items() if int(k) in mountings}
    (out / "metadata.json").write_text(json.dumps(meta))
    shutil.copy(folder / "darks.csv", out / "darks.csv")
    with open(folder / "points.csv", newline="") as source, open(out / "points.csv", "w", newline="") as target:
        reader = csv.DictReader(source)
        writer = csv.DictWriter(target, fieldnames=reader.fieldnames, lineterminator="\n")
        writer.writeheader()
        wanted = {str(m) for m in mountings}
        writer.writerows(row for row in reader if row["mounting"] in wanted)
    return out


def _mounting_means(folder: Path, theta_i: float, view: float) -> tuple[np.ndarray, np.ndarray]:
    """Each mounting's mean value at a planned geometry and its noise (every component that
    differs between mountings' readings, the mounting itself excluded), relative."""
    readings = read_readings(folder, "monitor")
    rows = readings.index[(np.abs(readings.column("theta_i") - theta_i) < 1e-6)
                          & (np.abs(readings.column("view") - view) < 1e-6)
                          & (readings.column("block") != CHECK_BLOCK) & (readings.column("block") != REFERENCE_BLOCK)]
    mounting = readings.points["mounting"][rows]
    noise2 = sum(c[rows] ** 2 for name, c in readings.budget.items() if name not in COMMON)
    labels = np.unique(mounting)
    means = np.array([readings.value[rows][mounting == m].mean() for m in labels])
    noise = np.array([math.sqrt(np.mean(noise2[mounting == m]) / np.sum(mounting == m)) for m in labels])
    return means, noise / np.abs(means)


def remount_study() -> dict[str, Any]:
    """A1: the mounting component stated from groups of :data:`GROUP` mountings against the
    scatter of the other mountings' values, at each geometry."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gonio-bench-remounts-") as tmp:
        folder = Path(tmp) / "remounts"
        lab = Configuration("lab", "lab", "monitor", False, 105, realism="lab")
        measure_wall = measure(remount_protocol(), lab, lab.seed, folder)
        records = []
        groups = [list(range(k, k + GROUP)) for k in range(0, REMOUNTS - GROUP + 1, GROUP)]
        reduced_groups = [reduce_recording(_subrecording(folder, g, Path(tmp) / f"group-{k}"))
                          for k, g in enumerate(groups)]
        for name, theta_i, phi_i, view in GEOMETRIES:
            means, noise = _mounting_means(folder, theta_i, view)
            observed, stated = [], []
            for members, reduced in zip(groups, reduced_groups):
                k = int(np.argmin(np.abs(reduced.theta_i - theta_i) + np.abs(reduced.view - view)))
                mounting = reduced.budget["mounting"][k] / abs(reduced.radiance[k]) * math.sqrt(len(members))
                others = np.array([m for m in range(len(means)) if m not in members])
                observed.append(np.std(means[others] / np.mean(means[others]), ddof=1))
                stated.append(math.sqrt(mounting**2 + np.mean(noise[members] ** 2)))
            ratio = math.sqrt(np.mean(np.square(observed)) / np.mean(np.square(stated)))
            records.append({
                "geometry": name, "planned": [theta_i, phi_i, view], "mountings": len(means),
                "observed_relative": float(math.sqrt(np.mean(np.square(observed)))),
                "stated_relative_per_group": [float(v) for v in stated],
                "stated_relative_rms": float(math.sqrt(np.mean(np.square(stated)))),
                "readings_noise_relative": float(np.sqrt(np.mean(noise**2))),
                "ratio": ratio, "ratio_sampling_error": ratio / math.sqrt(2.0 * (len(means) - 1)),
                "within_target": RATIO_TARGET[0] <= ratio <= RATIO_TARGET[1]})
    return {"mountings": REMOUNTS, "group": GROUP, "readings_per_mounting": REMOUNT_READINGS, "seed": lab.seed,
            "geometries": records, "all_within_target": all(r["within_target"] for r in records),
            "measure_wall_s": measure_wall, "wall_s": time.perf_counter() - start}


def lab_fit_seed(seed: int, text: str, tmp: Path) -> dict[str, Any]:
    """A2 for one seed: the Fig 16 protocol in :data:`CHI2_MOUNTINGS` mountings on the lab
    rig, the true model fitted with the rig's errors as parameters."""
    folder = tmp / f"fig16-lab-{seed}"
    lab = Configuration("lab", "lab", "monitor", False, seed, realism="lab")
    measure(text, lab, seed, folder)
    reduced = reduce_recording(folder)
    dataset, priors = reduced.fit_inputs("per-incidence")
    result = fit(dataset, "oren-nayar", fixed={"ir_weight": 1.0}, priors=priors, mcmc=False, alignment="all",
                 stray_light=True).least_squares
    out: dict[str, Any] = {"seed": seed, "redchi": result.redchi, "dof": result.dof, "n_data": len(dataset.value)}
    for name, truth in TRUTH.items():
        value, error = result.values[name], result.stderr[name]
        out.update({name: value, f"{name}_stderr": error, f"{name}_normalised_error": (value - truth) / error})
    out["median_stated_relative"] = float(np.median(reduced.radiance_sigma / np.abs(reduced.radiance)))
    out["budget_median_relative"] = {k: v["median_relative"] for k, v in reduced.budget_summary()["components"].items()}
    out["consistency"] = dict(reduced.consistency)
    return out


def lab_chi_square_study(seeds: Sequence[int]) -> dict[str, Any]:
    """A2: reduced chi-square of the true model on the Fig 16 sweep in four mountings."""
    text = _with_sample_fields(FIG16.read_text(), f"mountings = {CHI2_MOUNTINGS}")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gonio-bench-uncertainty-") as tmp:
        per_seed = [lab_fit_seed(seed, text, Path(tmp)) for seed in seeds]
    median = float(np.median([r["redchi"] for r in per_seed]))
    rms = {name: float(np.sqrt(np.mean([r[f"{name}_normalised_error"] ** 2 for r in per_seed]))) for name in TRUTH}
    return {"configuration": {"key": "lab-mountings", "label": f"lab rig, Fig 16 in {CHI2_MOUNTINGS} mountings, "
                                                              "rig errors fitted", "realism": "lab"},
            "protocol": f"{FIG16.relative_to(ROOT)} with [sample] mountings = {CHI2_MOUNTINGS}",
            "fit": "oren-nayar (ir_weight=1), alignment='all', stray_light=True, calibration per incidence, least "
                   "squares, full covariance, no extra-noise term",
            "per_seed": per_seed, "median_redchi": median,
            "within_target": REDCHI_TARGET[0] <= median <= REDCHI_TARGET[1], "rms_normalised_error": rms,
            "wall_s": time.perf_counter() - start}


def _window_offset(emulator, rig, theta_i: float, phi_i: float, view: float) -> float:
    """The emulator's ground truth: the relative offset of the window's mean radiance from
    the untextured sample's at a geometry, over the pixels the rig's window covers."""
    from drivers.emulator.world import footprint_coverage

    scene = emulator.scene
    positions = (view, theta_i, phi_i)
    angles = scene.angles(positions)
    image = scene.holder.relative_image(scene.brdf, angles, ("truth",) + positions)
    roi = rig.roi_for_view(view)
    weights = footprint_coverage(emulator.optics, angles[2])[roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]
    window = image[roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]
    return float(np.sum(weights * window) / np.sum(weights) - 1.0)


def texture_study(seeds: Sequence[int]) -> dict[str, Any]:
    """A3: the window's true texture offset against the stated ``texture`` component, per sample."""
    text = ("[protocol]\nname = \"texture\"\n[sample]\nlabel = \"plaster\"\n"
            "[[block]]\ntheta_i = 30\nphi_i = 0\nview = [0, -20]\n")
    start = time.perf_counter()
    records = []
    with tempfile.TemporaryDirectory(prefix="gonio-bench-texture-") as tmp:
        for seed in seeds:
            folder = Path(tmp) / f"texture-{seed}"
            protocol = protocols.loads(text)
            with emulated_rig(SAMPLE, seed, name=f"bench-texture-{seed}", realism="lab") as (rig, emulator, change,
                                                                                              metadata):
                acquisition.run_protocol(protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                                         change_sample=lambda which, **how: change(which, REFERENCE_REFLECTANCE, **how))
                truth = {view: _window_offset(emulator, rig, 30.0, 0.0, view) for view in (0.0, -20.0)}
            reduced = reduce_recording(folder)
            stated = float(reduced.consistency["texture_relative"])
            records.append({"seed": seed, "stated": stated, "true_offset": truth,
                            "ratio": {str(v): t / stated for v, t in truth.items()}})
    ratios = {view: [r["ratio"][view] for r in records] for view in ("0.0", "-20.0")}
    rms = {view: float(np.sqrt(np.mean(np.square(v)))) for view, v in ratios.items()}
    return {"seeds": list(seeds), "per_seed": records, "rms_ratio": rms,
            "rms_ratio_sampling_error": 1.0 / math.sqrt(2.0 * len(seeds)),
            "median_stated": float(np.median([r["stated"] for r in records])),
            "true_offset_std": {view: float(np.std([r["true_offset"][float(view)] for r in records]))
                                for view in ("0.0", "-20.0")},
            "wall_s": time.perf_counter() - start}


def stated_uncertainty_study(seeds: Sequence[int]) -> dict[str, Any]:
    """A4: the median stated relative uncertainty of the shipped Fig 16 sweep on the lab rig."""
    start = time.perf_counter()
    records = []
    lab = Configuration("lab", "lab", "monitor", False, 0, realism="lab")
    with tempfile.TemporaryDirectory(prefix="gonio-bench-stated-") as tmp:
        for seed in seeds:
            folder = Path(tmp) / f"fig16-{seed}"
            measure(FIG16.read_text(), lab, seed, folder)
            reduced = reduce_recording(folder)
            relative = reduced.radiance_sigma / np.abs(reduced.radiance)
            records.append({"seed": seed, "median_relative": float(np.median(relative)),
                            "range_relative": [float(relative.min()), float(relative.max())],
                            "budget_median_relative": {k: v["median_relative"] for k, v in
                                                       reduced.budget_summary()["components"].items()}})
    median = float(np.median([r["median_relative"] for r in records]))
    return {"protocol": str(FIG16.relative_to(ROOT)), "per_seed": records, "median_relative": median,
            "within_target": STATED_TARGET[0] <= median <= STATED_TARGET[1], "wall_s": time.perf_counter() - start}


# --------------------------------------------------------------------------- output
def _ratio_panel(ax, studies: Sequence[Mapping[str, Any]], title: str) -> None:
    """Observed / stated standard deviation per geometry for several studies."""
    width = 0.8 / max(len(studies), 1)
    for k, (label, geometries) in enumerate(studies):
        x = np.arange(len(geometries)) + (k - (len(studies) - 1) / 2) * width
        ax.errorbar(x, [g["ratio"] for g in geometries],
                    yerr=[g.get("combined_sampling_error") or g["ratio_sampling_error"] for g in geometries],
                    fmt="o", color=f"C{k}", capsize=3, label=label)
    ax.axhspan(*RATIO_TARGET, color="C2", alpha=0.15, label=f"target {RATIO_TARGET[0]}-{RATIO_TARGET[1]}")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(range(len(GEOMETRIES)), [f"{n}\n({ti:g}, {pi:g}, {v:g})" for n, ti, pi, v in GEOMETRIES])
    ax.set_ylabel("observed / stated standard deviation")
    ax.set_title(title + " (bars: sampling error)", fontsize=10)
    ax.legend(fontsize=7)


def _chi2_panel(ax, studies: Sequence[Mapping[str, Any]], title: str) -> None:
    """Reduced chi-square per seed of the true model, with each study's median."""
    for k, study in enumerate(studies):
        seeds = [r["seed"] for r in study["per_seed"]]
        ax.plot(seeds, [r["redchi"] for r in study["per_seed"]], "o", color=f"C{k}",
                label=f"{study['configuration']['label']} (median {study['median_redchi']:.2f})")
        ax.axhline(study["median_redchi"], color=f"C{k}", ls="--", lw=1.0)
    ax.axhspan(*REDCHI_TARGET, color="C2", alpha=0.15, label=f"target median {REDCHI_TARGET[0]}-{REDCHI_TARGET[1]}")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(list(CHI2_SEEDS))
    ax.set_xlabel("emulator seed")
    ax.set_ylabel("reduced chi-square of the true model")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper left")


def chart(payload: Mapping[str, Any], path: Path) -> None:
    """Four panels: the lab rig's remountings and repeats, its chi-square with mountings; the
    idealised rig's repeats and chi-square.

    Parameters
    ----------
    payload : mapping
        The benchmark's JSON payload.
    path : Path
        PNG file to write.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.0, 8.4), layout="constrained")
    (a, b), (c, d) = fig.subplots(2, 2)
    lab = payload.get("lab", {})
    studies = []
    if "remounts" in lab:
        studies.append((f"remountings ({lab['remounts']['mountings']}; stated from groups of "
                        f"{lab['remounts']['group']})", lab["remounts"]["geometries"]))
    studies += [(r["configuration"]["label"] + " (repeats in one mounting)", r["geometries"])
                for r in payload.get("repeats", []) if r["configuration"].get("realism") == "lab"]
    _ratio_panel(a, studies, "Lab rig (default realism): remountings and repeats")
    if "chi_square" in lab:
        _chi2_panel(b, [lab["chi_square"]], "Lab rig: Fig 16 in 4 mountings, oren-nayar with the rig's errors")
    ideal = [r for r in payload.get("repeats", []) if r["configuration"].get("realism") != "lab"]
    _ratio_panel(c, [(r["configuration"]["label"], r["geometries"]) for r in ideal],
                 f"Idealised rig: repeats ({ideal[0]['repeats'] if ideal else 0} per geometry)")
    _chi2_panel(d, payload.get("chi_square", []), "Idealised rig: Fig 16, oren-nayar least squares")
    for ax in (a, b, c, d):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=110)


def print_table(payload: Mapping[str, Any]) -> None:
    """Print the ratios, the chi-square medians and which targets are met."""
    lab = payload.get("lab", {})
    if "remounts" in lab:
        r = lab["remounts"]
        print(f"A1 remountings ({r['mountings']}, stated from groups of {r['group']}):")
        for g in r["geometries"]:
            print(f"  {g['geometry']:<10} observed {g['observed_relative']:.2e}  stated {g['stated_relative_rms']:.2e}  "
                  f"ratio {g['ratio']:.3f} +- {g['ratio_sampling_error']:.3f}  {'met' if g['within_target'] else 'MISSED'}")
    if "chi_square" in lab:
        study = lab["chi_square"]
        values = " ".join(f"{r['redchi']:.2f}" for r in study["per_seed"])
        rms = ", ".join(f"{name} {value:.2f}" for name, value in study["rms_normalised_error"].items())
        print(f"A2 {study['configuration']['label']}: median redchi {study['median_redchi']:.3f} "
              f"({values}) {'met' if study['within_target'] else 'MISSED'}; rms normalised error {rms}")
    if "texture" in lab:
        t = lab["texture"]
        print(f"A3 texture: rms true offset / stated {t['rms_ratio']} (sampling error "
              f"{t['rms_ratio_sampling_error']:.2f}); median stated {t['median_stated']:.2e}")
    if "stated" in lab:
        print(f"A4 median stated relative uncertainty of the Fig 16 sweep: {lab['stated']['median_relative']:.2e} "
              f"{'met' if lab['stated']['within_target'] else 'MISSED'}")
    print(f"\n{'configuration':<50}{'geometry':<10}{'n':>5}{'observed':>11}{'stated':>11}{'ratio':>8}{'+-':>7}  target")
    for study in payload.get("repeats", []):
        for g in study["geometries"]:
            print(f"{study['configuration']['label']:<50}{g['geometry']:<10}{g['n']:>5}{g['observed_relative']:>11.2e}"
                  f"{g['stated_relative']:>11.2e}{g['ratio']:>8.3f}{g['ratio_sampling_error']:>7.3f}  "
                  f"{'met' if g['within_target'] else 'MISSED'}")
    print(f"\n{'configuration':<50}{'median redchi':>14}  per seed")
    for study in payload.get("chi_square", []):
        values = " ".join(f"{r['redchi']:.2f}" for r in study["per_seed"])
        print(f"{study['configuration']['label']:<50}{study['median_redchi']:>14.3f}  {values}  "
              f"{'met' if study['within_target'] else 'MISSED'}")
        rms = ", ".join(f"{name} {value:.2f}" for name, value in study["rms_normalised_error"].items())
        print(f"{'':<50}{'':>14}  rms normalised error: {rms}; "
              f"median |scale - E_0| / u(E_0) = {study['median_abs_scale_pull']:.3g}")
    print()
    for name, met in payload["targets_met"].items():
        print(f"target {name}: {'met' if met else 'MISSED'}")
    print(f"wall time {payload['wall_s']:.0f} s")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the studies, write the JSON and the chart, print the table; always 0."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lab-only", action="store_true", help="part A only (the lab rig)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    lab = {"remounts": remount_study(), "chi_square": lab_chi_square_study(CHI2_SEEDS),
           "texture": texture_study(TEXTURE_SEEDS), "stated": stated_uncertainty_study((0, 1, 2))}
    configurations = [c for c in CONFIGURATIONS if c.realism == "lab" or not args.lab_only]
    repeats = [repeat_study(c, REPEATS) for c in configurations]
    by_key = {c.key: c for c in CONFIGURATIONS}
    chi_square = [] if args.lab_only else [chi_square_study(by_key[key], CHI2_SEEDS) for key in CHI2_CONFIGURATIONS]
    targets_met = {f"ratio ({s['configuration']['key']})": s["all_within_target"] for s in repeats}
    targets_met.update({f"median redchi ({s['configuration']['key']}, ideal rig)": s["within_target"]
                        for s in chi_square})
    targets_met["remount ratio (lab)"] = lab["remounts"]["all_within_target"]
    targets_met["median redchi with mountings (lab)"] = lab["chi_square"]["within_target"]
    targets_met["median stated uncertainty 0.1-3 % (lab)"] = lab["stated"]["within_target"]
    payload = {
        "benchmark": "uncertainty",
        "command": "python benchmarks/bench_uncertainty.py" + (" --lab-only" if args.lab_only else ""),
        "machine": machine(),
        "sample": SAMPLE,
        "targets": {"ratio": list(RATIO_TARGET), "median_redchi": list(REDCHI_TARGET),
                    "median_stated_relative": list(STATED_TARGET),
                    "ratio_definition": "observed std of one reading (or one mounting's value) / stated std (the "
                                        "varying part of its budget)",
                    "redchi_definition": "result.least_squares.redchi of gonio.fitting.fit on Reduced.fit_inputs() "
                                         "(lab: calibration per incidence, alignment='all', stray_light=True); no "
                                         "extra-noise term"},
        "lab": lab,
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

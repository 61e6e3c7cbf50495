"""Rendered-surface tables: how far and how jagged their error is, and what they cost.

A rendered surface becomes an emulated sample through a table of its BRDF
(gonio.surfaces.table).  This script measures, for the V-groove field (sigma = 30 deg),
the isotropic single-slope groove (theta_a = 40 deg) and the height field (sigma =
30 deg), rho = 0.9, all bounces, the default grids and paths per node, the node
estimators a table can use:

``previous``
    every order sampled, each node with its own random stream (the tables of renderer
    version 1; for the height field, where nothing is known exactly, still the table's
    node estimator);
``independent``
    the grooves' exactly known orders (``oren-nayar-exact``'s two bounces; eq 29/46 for
    one slope) plus the sampled rest with the light of each bounce integrated over the
    other facet (``expected_bounces``), each node with its own stream;
``common``
    the same with one stream for every node (common random numbers): the grooves'
    table node estimator (gonio.surfaces.table.node_values); for the height field,
    every order sampled with common random numbers.

Measured:

* node errors against a reference of many more paths (independent streams, another
  seed) on lines of nodes along each table axis: the size of the error (rms) and its
  jagged part, the rms of the second differences along the lines over sqrt(6) (equal to
  the rms for independent errors, near 0 for a smooth error), with the reference's own
  white noise for comparison;
* the stated node errors against the reference: rms of z;
* the grooves' reference (exact low orders, expected bounces) against plain all-bounce
  renders (the independent method, many paths): rms of z;
* the interpolated table (what the emulated rig measures) against the reference on the
  in-plane sweeps theta_i = 30, 60, 75 deg and at random geometries;
* what a fit sees of the sample's error: ``oren-nayar-tabulated`` (rho, sigma; the scale
  is calibrated) fitted by least squares on the relative residuals to the sample's values at the
  126 geometries the demo measures (Figs 16 and 19), for six Monte Carlo seeds of each
  estimator (evaluated at the geometries themselves: the noise alone, without
  interpolation), 20000 and 80000 paths: the spread of the fitted parameters over seeds,
  and the rms of the residuals' change against the fit to the reference (the part of the
  error no parameter absorbs);
* table build time of each estimator (same threads, same run) and of
  gonio.surfaces.table.render_table, also for the tables with nothing sampled (pits,
  grooves at two bounces, on their finer grids), each against the previous estimator
  (every order sampled, on the kind's sampled-table grid) in the same run.

Run:  python benchmarks/surfaces_tables.py   (about 30 min on 2 shared cores)
Writes docs/benchmarks/surfaces_tables.json and surfaces_tables.png; ``--charts`` redraws
the chart from the JSON, ``--fits`` redoes the fits alone and ``--exact`` the exact
tables alone, updating the JSON, a kind
(``vgrooves``, ``vgroove``, ``heightfield``) on the command line redoes that kind alone.
"""
from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Callable

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json  # noqa: E402

from gonio.surfaces import render  # noqa: E402
from gonio.surfaces.analytic import known_orders  # noqa: E402
from gonio.surfaces.spec import SurfaceSpec, parse_surface_spec  # noqa: E402
from gonio.surfaces.table import (  # noqa: E402
    COMMON_RANDOM_NUMBERS,
    FLOOR,
    GRIDS,
    SurfaceTable,
    grid_for,
    node_geometries,
    node_values,
    render_table,
)

WORKERS = 2
SPECS = {"vgrooves": "kind=vgrooves,sigma=30,rho=0.9", "vgroove": "kind=vgroove,theta_a=40,rho=0.9",
         "heightfield": "kind=heightfield,sigma=30,rho=0.9"}
#: Tables with nothing sampled, timed against the previous estimator.
EXACT_SPECS = ("kind=vgrooves,sigma=30,rho=0.9,bounces=2", "kind=vgroove,theta_a=40,rho=0.9,bounces=2",
               "kind=pits,psi=60,coverage=1,rho=0.9")
#: Paths per geometry of the references (the height field samples every order: more
#: paths would cost minutes per thousand geometries).
REFERENCE_PATHS = {"vgrooves": 800_000, "vgroove": 800_000, "heightfield": 400_000}
#: The same for the in-plane sweeps and the random geometries (fewer: more geometries).
SWEEP_PATHS = {"vgrooves": 200_000, "vgroove": 200_000, "heightfield": 100_000}
REFERENCE_SEED = 1000
#: Plain all-bounce renders that check the V-groove reference (an independent method).
CHECK_PATHS, CHECK_NODES = 1_000_000, 24
SWEEP_INCIDENCES = (30.0, 60.0, 75.0)
SWEEP_VIEWS = np.arange(-88.0, 88.5, 2.0)
RANDOM_GEOMETRIES = 200
#: Node lines: (axis, fixed indices of the other two axes as fractions of their length).
LINES = [("y", (0.5, 0.5)), ("y", (1.0, 0.0)), ("y", (0.25, 0.8)),
         ("zeta", (0.5, 0.5)), ("zeta", (0.2, 0.15)), ("zeta", (0.8, 0.8)),
         ("t", (0.5, 0.5)), ("t", (0.2, 0.9)), ("t", (0.8, 0.15))]
AXES = ("y", "zeta", "t")
#: The kinds with exact low orders and expected bounces.
GROOVES = ("vgrooves", "vgroove")
#: The estimator each kind's tables use (gonio.surfaces.table.COMMON_RANDOM_NUMBERS).
TABLE_ESTIMATOR = {kind: ("common" if COMMON_RANDOM_NUMBERS[kind] else "independent" if kind in GROOVES else "previous")
                   for kind in SPECS}


def line_indices(shape: tuple[int, int, int]) -> list[tuple[str, np.ndarray]]:
    """Flat node indices of each line of :data:`LINES` on a grid of ``shape``."""
    lines = []
    for axis, fractions in LINES:
        k = AXES.index(axis)
        others = [a for a in range(3) if a != k]
        index = [0, 0, 0]
        for other, fraction in zip(others, fractions):
            index[other] = int(round(fraction * (shape[other] - 1)))
        cells = []
        for i in range(shape[k]):
            index[k] = i
            cells.append(np.ravel_multi_index(tuple(index), shape))
        lines.append((f"{axis} at {dict(zip([AXES[o] for o in others], fractions))}", np.array(cells)))
    return lines


def previous_values(spec: SurfaceSpec, ti, tr, dphi) -> tuple[np.ndarray, np.ndarray]:
    rendered = render(spec.surface, ti, 0.0, tr, dphi, paths=spec.paths, seed=spec.seed, bounces=spec.bounces)
    return rendered.value, rendered.standard_error


ESTIMATORS: dict[str, Callable] = {
    "previous": previous_values,
    "independent": lambda spec, ti, tr, dphi: node_values(spec, ti, tr, dphi, common_random_numbers=False),
    "common": lambda spec, ti, tr, dphi: node_values(spec, ti, tr, dphi, common_random_numbers=True),
}


def threaded(function: Callable, spec: SurfaceSpec, ti, tr, dphi, batch: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """``function(spec, ...)`` on batches of geometries in :data:`WORKERS` threads."""
    value, error = np.empty(ti.size), np.empty(ti.size)

    def task(first: int) -> None:
        part = slice(first, first + batch)
        value[part], error[part] = function(spec, ti[part], tr[part], dphi[part])

    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        list(pool.map(task, range(0, ti.size, batch)))
    return value, error


def reference(kind: str, spec: SurfaceSpec, ti, tr, dphi, paths: int) -> tuple[np.ndarray, np.ndarray]:
    """Many paths, independent streams, another seed: the exact-low-order estimator for
    the V-groove field (checked against plain renders), plain renders for the height field."""
    many = replace(spec, paths=paths, seed=REFERENCE_SEED)
    function = ESTIMATORS["independent"] if kind in GROOVES else previous_values
    return threaded(function, many, np.asarray(ti, float), np.asarray(tr, float), np.asarray(dphi, float), batch=4)


def roughness(relative: np.ndarray, lines, moderate: np.ndarray) -> dict:
    """Size and jaggedness of the relative errors on the node lines: rms; rms of the
    second differences along the lines over sqrt(6) (the rms again for independent
    errors, near 0 for a smooth error); the same on the nodes with polar angles up to
    80 deg (``moderate``: every node of a second difference); and the median over the
    lines of their jagged part over their rms (1 for independent errors)."""
    values, second, second_moderate, ratios = [], [], [], []
    for _, cells in lines:
        e = relative[cells]
        d2 = e[:-2] - 2.0 * e[1:-1] + e[2:]
        inner = moderate[cells][:-2] & moderate[cells][1:-1] & moderate[cells][2:]
        values.append(e)
        second.append(d2)
        second_moderate.append(d2[inner])
        ratios.append(np.sqrt(np.mean(d2**2) / 6.0) / np.sqrt(np.mean(e**2)))
    every = np.concatenate(values)
    mask = np.concatenate([moderate[cells] for _, cells in lines])
    rms = (lambda a: float(np.sqrt(np.mean(np.square(a)))))  # noqa: E731
    return {"rms_relative_error": rms(every), "jagged_relative_error": rms(np.concatenate(second)) / np.sqrt(6.0),
            "rms_relative_error_to_80deg": rms(every[mask]),
            "jagged_relative_error_to_80deg": rms(np.concatenate(second_moderate)) / np.sqrt(6.0),
            "median_line_jagged_over_rms": float(np.median(ratios))}


def node_statistics(values, errors, ref, ref_error, lines, moderate) -> dict:
    relative = values / ref - 1.0
    z = (values - ref) / np.hypot(errors, ref_error)
    return {**roughness(relative, lines, moderate), "max_relative_error": float(np.max(np.abs(relative))),
            "median_stated_relative_error": float(np.median(errors / ref)),
            "rms_z": float(np.sqrt(np.mean(z**2))), "relative_error": relative.tolist()}


def sweep_geometries() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ti = np.repeat(SWEEP_INCIDENCES, SWEEP_VIEWS.size)
    views = np.tile(SWEEP_VIEWS, len(SWEEP_INCIDENCES))
    return ti, np.abs(views), np.where(views >= 0.0, 0.0, 180.0)


def random_geometries() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    polar = lambda: np.degrees(np.arccos(rng.uniform(np.cos(np.radians(85.0)), 1.0, RANDOM_GEOMETRIES)))  # noqa: E731
    return polar(), polar(), rng.uniform(0.0, 180.0, RANDOM_GEOMETRIES)


def study(kind: str) -> dict:
    spec = parse_surface_spec(SPECS[kind])
    grid = GRIDS[kind]
    alpha, beta, dphi = (np.degrees(a).ravel() for a in node_geometries(grid))
    lines = line_indices(grid.shape)
    on_lines = np.unique(np.concatenate([cells for _, cells in lines]))
    estimators = ["previous", "common"] if kind == "heightfield" else list(ESTIMATORS)
    render(spec.surface, 30.0, 0.0, 40.0, 0.0, paths=100, expected_bounces=True)  # compile, realise
    out: dict = {"spec": "surface:" + spec.text(), "grid": list(grid.shape), "nodes": int(alpha.size),
                 "line_nodes": int(on_lines.size), "reference_paths": REFERENCE_PATHS[kind],
                 "sweep_reference_paths": SWEEP_PATHS[kind],
                 "lines": [name for name, _ in lines], "estimators": {}}
    print(f"{kind}: reference on {on_lines.size} line nodes", flush=True)
    ref, ref_error = np.zeros(alpha.size), np.zeros(alpha.size)
    ref[on_lines], ref_error[on_lines] = reference(kind, spec, beta[on_lines], alpha[on_lines], dphi[on_lines],
                                                       REFERENCE_PATHS[kind])
    out["reference_median_relative_error"] = float(np.median(ref_error[on_lines] / ref[on_lines]))
    out["reference_rms_relative_error"] = float(np.sqrt(np.mean((ref_error[on_lines] / ref[on_lines]) ** 2)))
    moderate = alpha[on_lines] <= 80.0
    out["reference_rms_relative_error_to_80deg"] = float(np.sqrt(np.mean((ref_error[on_lines] / ref[on_lines])[moderate]
                                                                         ** 2)))
    if kind in GROOVES:
        picked = on_lines[np.linspace(0, on_lines.size - 1, CHECK_NODES).astype(int)]
        plain = replace(spec, paths=CHECK_PATHS, seed=REFERENCE_SEED + 1)
        value, error = threaded(previous_values, plain, beta[picked], alpha[picked], dphi[picked], batch=2)
        z = (value - ref[picked]) / np.hypot(error, ref_error[picked])
        out["reference_against_plain_renders"] = {"nodes": CHECK_NODES, "paths": CHECK_PATHS,
                                                  "rms_z": float(np.sqrt(np.mean(z**2))),
                                                  "max_abs_z": float(np.max(np.abs(z))),
                                                  "median_plain_relative_error": float(np.median(error / value))}
        print(f"  reference against plain renders: {out['reference_against_plain_renders']}", flush=True)
    sweep, scattered = sweep_geometries(), random_geometries()
    sweep_ref = reference(kind, spec, *sweep, SWEEP_PATHS[kind])
    scattered_ref = reference(kind, spec, *scattered, SWEEP_PATHS[kind])
    out["sweep"] = {"theta_i": sweep[0].tolist(), "views": np.tile(SWEEP_VIEWS, len(SWEEP_INCIDENCES)).tolist(),
                    "reference": sweep_ref[0].tolist(), "reference_error": sweep_ref[1].tolist()}
    for name in estimators:
        start, cpu = time.perf_counter(), time.process_time()
        values, errors = threaded(ESTIMATORS[name], spec, beta, alpha, dphi)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        entry = node_statistics(values[on_lines], errors[on_lines], ref[on_lines], ref_error[on_lines],
                                [(n, np.searchsorted(on_lines, cells)) for n, cells in lines],
                                alpha[on_lines] <= 80.0)
        entry.update(build_seconds=seconds, build_cpu_seconds=cpu,
                     node_relative_error_median=float(np.median(errors / values)),
                     node_relative_error_max=float(np.max(errors / values)))
        table = SurfaceTable(np.log(values + FLOOR).reshape(grid.shape))
        deviation = table(sweep[0], 0.0, sweep[1], sweep[2]) / sweep_ref[0] - 1.0
        entry["sweep_deviation"] = deviation.tolist()
        entry["sweep_rms_deviation"] = float(np.sqrt(np.mean(deviation**2)))
        random_dev = table(scattered[0], 0.0, scattered[1], scattered[2]) / scattered_ref[0] - 1.0
        entry["random_geometries"] = {"rms": float(np.sqrt(np.mean(random_dev**2))),
                                      "median_abs": float(np.median(np.abs(random_dev))),
                                      "p99_abs": float(np.percentile(np.abs(random_dev), 99))}
        out["estimators"][name] = entry
        print(f"  {name}: build {seconds:.1f} s, node error median {entry['node_relative_error_median']:.2e} "
              f"max {entry['node_relative_error_max']:.2e}; vs reference rms {entry['rms_relative_error']:.2e}, "
              f"jagged {entry['jagged_relative_error']:.2e}, rms z {entry['rms_z']:.2f}; sweep rms "
              f"{entry['sweep_rms_deviation']:.2e}; random {entry['random_geometries']}", flush=True)
    out["fit_jitter"] = fit_jitter(kind)
    out["random_reference_median_relative_error"] = float(np.median(scattered_ref[1] / scattered_ref[0]))
    out["sweep_reference_median_relative_error"] = float(np.median(sweep_ref[1] / sweep_ref[0]))
    start, cpu = time.perf_counter(), time.process_time()
    render_table(spec, grid, workers=WORKERS)
    out["render_table_seconds"] = time.perf_counter() - start
    out["render_table_cpu_seconds"] = time.process_time() - cpu
    return out


def demo_geometries() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(theta_i, theta_r, phi_r - phi_i) [deg] of the 126 points the demo measures: the
    Fig 16 and Fig 19 sweeps (protocols/), without the in-plane views within 5 deg of the
    lamp, which the rig refuses (camera and lamp too close)."""
    rows = [(ti, abs(v), 0.0 if v >= 0 else 180.0) for ti in (30.0, 45.0, 60.0) for v in range(-80, 81, 5)
            if abs(v - ti) > 5.0]
    rows += [(ti, v, dphi) for ti, dphi in ((60.0, 45.0), (75.0, 60.0)) for v in range(0, 86, 5)]
    return tuple(np.array(column, float) for column in zip(*rows))


def fitted(values: np.ndarray, geometry) -> tuple[np.ndarray, np.ndarray]:
    """(rho, sigma) of ``oren-nayar-tabulated`` fitted to ``values`` by least squares on
    the relative residuals, and those residuals.  Absolute: the demo calibrates its
    scale on a reflectance standard (a prior of 3e-5 relative), so the scale is not free."""
    from scipy.optimize import least_squares

    import gonio

    fast = gonio.models.get("oren-nayar-tabulated").at(geometry[0], 0.0, geometry[1], geometry[2])
    result = least_squares(lambda x: fast(rho=x[0], sigma=x[1]) / values - 1.0, [0.9, 30.0],
                           bounds=([0.0, 0.0], [1.0, 90.0]), x_scale="jac", xtol=1e-12, ftol=1e-12)
    return result.x, result.fun


FIT_SEEDS = 6
FIT_PATHS = (20_000, 80_000)


def fit_jitter(kind: str) -> dict:
    """The fit's parameters over Monte Carlo seeds of the sample, and the part of the
    sample's error the fit cannot absorb: the rms over the geometries of the difference
    between the fit's residuals to the sample and to the reference (what the sample's
    noise adds to the residuals; at the rig's 1e-4 relative precision, a reduced
    chi-square of about (rms / 1e-4)^2)."""
    spec = parse_surface_spec(SPECS[kind])
    geometry = demo_geometries()
    ref, ref_error = reference(kind, spec, *geometry, REFERENCE_PATHS[kind])
    ref_fit, ref_residual = fitted(ref, geometry)
    out = {"geometries": int(geometry[0].size), "reference": dict(zip(("rho", "sigma"), ref_fit.tolist())),
           "reference_rms_residual": float(np.sqrt(np.mean(ref_residual**2))),
           "reference_median_relative_error": float(np.median(ref_error / ref)), "rows": []}
    if kind in GROOVES:
        cases = [("common", paths) for paths in FIT_PATHS] + [("independent", spec.paths), ("previous", spec.paths)]
    else:
        cases = [("previous", paths) for paths in FIT_PATHS] + [("common", spec.paths)]
    for name, paths in cases:
        fits, unabsorbed, raw = [], [], []
        for seed in range(FIT_SEEDS):
            values, _ = threaded(ESTIMATORS[name], replace(spec, paths=paths, seed=seed), *geometry)
            parameters, residual = fitted(values, geometry)
            fits.append(parameters)
            unabsorbed.append(float(np.sqrt(np.mean((residual - ref_residual) ** 2))))
            raw.append(float(np.sqrt(np.mean((values / ref - 1.0) ** 2))))
        rho, sigma = np.array(fits).T
        row = {"estimator": name, "paths": paths, "seeds": FIT_SEEDS, "rho": rho.tolist(), "sigma": sigma.tolist(),
               "rho_sd": float(np.std(rho, ddof=1)), "sigma_sd": float(np.std(sigma, ddof=1)),
               "rms_error": float(np.sqrt(np.mean(np.square(raw)))),
               "rms_unabsorbed": float(np.sqrt(np.mean(np.square(unabsorbed))))}
        out["rows"].append(row)
        print(f"  fit {kind} {name} {paths}: rms error {row['rms_error']:.2e}, unabsorbed {row['rms_unabsorbed']:.2e}; "
              f"sd rho {row['rho_sd']:.1e}, sigma {row['sigma_sd']:.3f} deg "
              f"(reference fit {out['reference']})", flush=True)
    return out


def interpolation_errors(spec: SurfaceSpec, arrays: dict, grid) -> dict:
    """The exact table of ``spec`` and the same closed form tabulated on the sampled-table
    ``grid``, against the closed form at 3000 random geometries (polar angles uniform in
    solid angle up to 89 deg) and at the demo's 126 geometries: median, 99th percentile
    and max of the relative error, and its rms at the demo's."""
    rng = np.random.default_rng(11)
    polar = lambda: np.degrees(np.arccos(rng.uniform(np.cos(np.radians(89.0)), 1.0, 3000)))  # noqa: E731
    scattered = (polar(), polar(), rng.uniform(0.0, 180.0, 3000))
    alpha, beta, dphi = (np.degrees(a).ravel() for a in node_geometries(grid))
    coarse = SurfaceTable(np.log(known_orders(spec.surface, beta, 0.0, alpha, dphi, spec.bounces).value + FLOOR)
                          .reshape(grid.shape))
    out = {}
    for label, table in (("exact_grid", SurfaceTable(arrays["log_brdf"])), ("sampled_grid", coarse)):
        for where, (ti, tr, dp) in (("random", scattered), ("demo", demo_geometries())):
            truth = known_orders(spec.surface, ti, 0.0, tr, dp, spec.bounces).value
            error = np.abs(table(ti, 0.0, tr, dp) / truth - 1.0)
            out[f"{label}_{where}"] = {"median": float(np.median(error)), "p99": float(np.percentile(error, 99)),
                                       "max": float(error.max()), "rms": float(np.sqrt(np.mean(error**2)))}
    return out


def exact_builds() -> list[dict]:
    """render_table of the tables with nothing sampled, and the previous estimator (every
    order sampled on the kind's sampled-table grid) in the same run; their interpolation
    errors."""
    rows = []
    for text in EXACT_SPECS:
        spec = parse_surface_spec(text)
        start, cpu = time.perf_counter(), time.process_time()
        arrays = render_table(spec, workers=WORKERS)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        grid = GRIDS[spec.surface.kind]
        alpha, beta, dphi = (np.degrees(a).ravel() for a in node_geometries(grid))
        start, previous_cpu = time.perf_counter(), time.process_time()
        threaded(previous_values, spec, beta, alpha, dphi)
        previous, previous_cpu = time.perf_counter() - start, time.process_time() - previous_cpu
        rows.append({"spec": "surface:" + spec.text(), "grid": list(grid_for(spec).shape),
                     "nodes": int(arrays["log_brdf"].size), "seconds": seconds, "cpu_seconds": cpu,
                     "previous_grid": list(grid.shape), "previous_seconds": previous,
                     "previous_cpu_seconds": previous_cpu, "ratio_to_previous": seconds / previous,
                     "interpolation": interpolation_errors(spec, arrays, grid)})
        print(f"{text}: {seconds:.1f} s on {arrays['log_brdf'].size} nodes; previous {previous:.1f} s; "
              f"interpolation {rows[-1]['interpolation']}", flush=True)
    return rows


def chart(payload: dict) -> None:
    colours = {"previous": "tab:grey", "independent": "tab:blue", "common": "tab:red"}
    kinds = list(payload["kinds"])
    figure = Figure(figsize=(12, 3.4 * len(kinds)))
    for row, kind in enumerate(kinds):
        entry = payload["kinds"][kind]
        ti, views = np.array(entry["sweep"]["theta_i"]), np.array(entry["sweep"]["views"])
        ref_error = np.array(entry["sweep"]["reference_error"]) / np.array(entry["sweep"]["reference"])
        for col, incidence in enumerate(SWEEP_INCIDENCES):
            ax = figure.add_subplot(len(kinds), len(SWEEP_INCIDENCES), row * len(SWEEP_INCIDENCES) + col + 1)
            chosen = ti == incidence
            ax.fill_between(views[chosen], -200 * ref_error[chosen], 200 * ref_error[chosen], color="0.85",
                            label="reference, 2 standard errors")
            for name, values in entry["estimators"].items():
                now = " (the tables' now)" if name == TABLE_ESTIMATOR[kind] else ""
                ax.plot(views[chosen], 100 * np.array(values["sweep_deviation"])[chosen], color=colours[name],
                        lw=1.6 if now else 0.9, label=f"table, {name} nodes{now}")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_title(f"{kind}: theta_i = {incidence:g} deg, in the plane", fontsize=9)
            ax.set_xlabel("signed viewing angle [deg] (positive: source side)", fontsize=8)
            if col == 0:
                ax.set_ylabel("table / reference - 1 [%]", fontsize=8)
            if col == 0:
                ax.legend(fontsize=7)
    figure.subplots_adjust(hspace=0.45, wspace=0.25, left=0.07, right=0.98, top=0.93, bottom=0.1)
    figure.savefig(OUT / "surfaces_tables.png", dpi=110)


def main() -> None:
    if {"--charts", "--fits", "--exact"} & set(sys.argv[1:]):
        import json

        payload = json.loads((OUT / "surfaces_tables.json").read_text())
        if "--exact" in sys.argv[1:]:
            payload["exact_tables"] = exact_builds()
            write_json("surfaces_tables", payload)
        if "--fits" in sys.argv[1:]:
            for kind, entry in payload["kinds"].items():
                if kind in sys.argv[1:] or not any(k in sys.argv[1:] for k in SPECS):
                    entry["fit_jitter"] = fit_jitter(kind)
            write_json("surfaces_tables", payload)
        chart(payload)
        return
    start, cpu = time.perf_counter(), time.process_time()
    chosen = [k for k in SPECS if k in sys.argv[1:]]
    if chosen:  # redo these kinds alone, keep the rest of the JSON
        import json

        payload = json.loads((OUT / "surfaces_tables.json").read_text())
        payload.setdefault("partial_runs", []).append({"kinds": chosen, "load_average_at_start": list(os.getloadavg())})
        payload["kinds"].update({kind: study(kind) for kind in chosen})
    else:
        payload = {"machine": machine(), "load_average_at_start": list(os.getloadavg()), "workers": WORKERS,
                   "kinds": {kind: study(kind) for kind in SPECS}, "exact_tables": exact_builds()}
    payload["seconds"], payload["cpu_seconds"] = time.perf_counter() - start, time.process_time() - cpu
    write_json("surfaces_tables", payload)
    chart(payload)
    print(f"done in {payload['seconds'] / 60:.1f} min ({payload['cpu_seconds'] / 60:.1f} min CPU)")


if __name__ == "__main__":
    main()

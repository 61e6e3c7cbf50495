"""How far the papers' models are from the surfaces they describe, rendered.

Renders, by Monte Carlo path tracing with all bounces (gonio.surfaces), at rho = 0.9:

* the Gaussian V-groove field (Oren & Nayar's own surface model, eq 31-32) and the
  Gaussian height field matched to it (same rms facet slope angle) at
  sigma = 10, 20, 30, 40 deg;
* pitted planes (Koenderink et al. 1999) at psi = 30, 60, 90 deg (coverage 1) and
  psi = 90 deg, coverage 0.5;

on a set of geometries in the plane of incidence, out of it and at grazing angles, and
compares ``oren-nayar-exact`` (two bounces, exact), ``oren-nayar`` (eq 33-35),
``oren-nayar-qualitative`` (eq 36) and ``pitted`` with them: at the surfaces' own
parameters, and fitted (least squares on the relative differences, every parameter
free; ``oren-nayar-tabulated`` stands for the exact model in the fits).  Also: what the
bounces beyond two add, by rho and sigma (directional-hemispherical reflectance split by
scattering order, and per geometry); in-plane curves like the paper's Fig 10; the speed
of the kernel per kind against the numpy Monte Carlo of Koenderink et al. section 4.1 in
the same run (table builds: benchmarks/surfaces_tables.py).

Run:  python benchmarks/surfaces_study.py   (about 10 min of CPU on 2 cores)
Writes docs/benchmarks/surfaces.json, surfaces_fig10.png, surfaces_pits.png,
surfaces_summary.png and docs/surfaces-study.md.  ``--charts`` redraws the charts and the
page from the JSON without rendering.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.fitting.discrepancy import OFFSETS_FILE, offsets_from_study  # noqa: E402
from gonio.surfaces import HeightField, PittedPlane, VGrooveField, render, render_albedo  # noqa: E402
from gonio.surfaces.shapes import rms_slope_angle  # noqa: E402

RHO = 0.9
SIGMAS = (10.0, 20.0, 30.0, 40.0)
PITS = ((30.0, 1.0), (60.0, 1.0), (90.0, 1.0), (90.0, 0.5))
#: Paths per geometry of the comparison renders (MC errors: in the JSON and the page).
PATHS = {"vgrooves": 200_000, "heightfield": 200_000, "pits": 200_000}
FIG10_PATHS = 100_000
ALBEDO_RHOS = (0.5, 0.7, 0.9, 0.95, 1.0)
ALBEDO_PATHS = 200_000
WORKERS = 2
ON_MODELS = ("oren-nayar-exact", "oren-nayar", "oren-nayar-qualitative")
FIT_MODELS = {  # model: (free parameters, start, fixed options)
    "oren-nayar-tabulated": (("rho", "sigma"), (0.9, 25.0), {}),
    "oren-nayar": (("rho", "sigma"), (0.9, 25.0), {"ir_weight": 1.0}),
    "oren-nayar-qualitative": (("rho", "sigma"), (0.9, 25.0), {}),
    "pitted": (("rho", "psi", "coverage"), (0.9, 60.0, 0.8), {}),
}


def study_geometries() -> dict[str, np.ndarray]:
    """In-plane sweeps, off-plane triples and a grazing set, with a subset label each."""
    rows = []
    for ti in (0.0, 30.0, 60.0, 75.0, 85.0):
        for view in np.arange(-85.0, 86.0, 10.0):
            rows.append((ti, abs(view), 0.0 if view >= 0 else 180.0, "in-plane"))
    for ti in (30.0, 60.0, 80.0):
        for tr in (20.0, 50.0, 80.0):
            for dphi in (45.0, 90.0, 135.0):
                rows.append((ti, tr, dphi, "out-of-plane"))
    for ti, tr, dphi in ((88.0, 88.0, 0.0), (88.0, 88.0, 180.0), (88.0, 60.0, 0.0), (88.0, 60.0, 180.0),
                         (88.0, 30.0, 90.0), (85.0, 89.0, 20.0), (89.0, 5.0, 0.0), (80.0, 88.0, 150.0)):
        rows.append((ti, tr, dphi, "grazing"))
    ti, tr, dphi, label = zip(*rows)
    label = np.array(label)
    grazing = (np.maximum(ti, tr) >= 80.0)
    return {"theta_i": np.array(ti), "theta_r": np.array(tr), "delta_phi": np.array(dphi), "subset": label,
            "grazing": grazing}


def surfaces() -> list[tuple[str, object]]:
    out = [(f"vgrooves sigma={s:g}", VGrooveField(s, RHO)) for s in SIGMAS]
    out += [(f"heightfield sigma={s:g}", HeightField(s, RHO)) for s in SIGMAS]
    out += [(f"pits psi={p:g} coverage={c:g}", PittedPlane(p, c, RHO)) for p, c in PITS]
    return out


def nominal_parameters(surface) -> dict[str, dict]:
    """The models compared at the surface's own parameters."""
    if isinstance(surface, PittedPlane):
        return {"pitted": {"rho": surface.rho, "psi": surface.psi, "coverage": surface.coverage}}
    return {model: {"rho": surface.rho, "sigma": surface.sigma} for model in ON_MODELS}


def differences(model_values: np.ndarray, rendered, geometries: dict) -> dict:
    """rms and max relative difference (model / render - 1) by subset, and rms of z."""
    relative = model_values / rendered.value - 1.0
    z = (model_values - rendered.value) / np.maximum(rendered.standard_error, 1e-300)
    out = {}
    masks = {"all": np.ones(relative.size, bool), "in-plane": geometries["subset"] == "in-plane",
             "out-of-plane": geometries["subset"] == "out-of-plane", "grazing (>= 80 deg)": geometries["grazing"],
             "theta <= 80 deg": ~geometries["grazing"]}
    for name, mask in masks.items():
        worst = int(np.flatnonzero(mask)[np.argmax(np.abs(relative[mask]))])
        out[name] = {"rms": float(np.sqrt(np.mean(relative[mask] ** 2))), "max": float(np.abs(relative[worst])),
                     "signed_max": float(relative[worst]), "rms_z": float(np.sqrt(np.mean(z[mask] ** 2))),
                     "worst_geometry": [float(geometries[k][worst]) for k in ("theta_i", "theta_r", "delta_phi")]}
    return out


def fit(model: str, rendered, geometries: dict) -> dict:
    """Least squares on the relative differences at polar angles <= 80 deg (the grazing
    rim, where some models are off by factors, would otherwise decide the fit), every
    parameter of FIT_MODELS free; the differences are then reported everywhere."""
    from scipy.optimize import least_squares

    names, start, options = FIT_MODELS[model]
    spec = gonio.models.get(model)
    bounds = [dict((p.name, p.bounds) for p in spec.params)[n] for n in names]
    fast = spec.at(geometries["theta_i"], 0.0, geometries["theta_r"], geometries["delta_phi"])
    moderate = ~geometries["grazing"]

    def residual(x):
        return (fast(**dict(zip(names, x)), **options) / rendered.value - 1.0)[moderate]

    low = [max(b[0], 1e-6) for b in bounds]
    high = [b[1] for b in bounds]
    best = None
    for guess in (start, [0.7] + list(start[1:])):
        result = least_squares(residual, np.clip(guess, low, high), bounds=(low, high), x_scale="jac")
        if best is None or result.cost < best.cost:
            best = result
    values = fast(**dict(zip(names, best.x)), **options)
    return {"parameters": dict(zip(names, map(float, best.x))), **differences(values, rendered, geometries)}


def compare(geometries: dict) -> list[dict]:
    rows = []
    for label, surface in surfaces():
        paths = PATHS[surface.kind]
        start, cpu = time.perf_counter(), time.process_time()
        rendered = render(surface, geometries["theta_i"], 0.0, geometries["theta_r"], geometries["delta_phi"],
                          paths=paths, seed=1, workers=WORKERS)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        relative_error = rendered.standard_error / rendered.value
        higher = rendered.orders[2] / rendered.value
        two_bounce = rendered.cumulative[1]
        row = {"surface": label, "kind": surface.kind, "parameters": surface.parameters(), "paths": paths,
               "render_seconds": seconds, "render_cpu_seconds": cpu,
               "mc_relative_error": {"median": float(np.median(relative_error)), "max": float(np.max(relative_error))},
               "beyond_two_bounces": {"median": float(np.median(higher)), "max": float(np.max(higher)),
                                      "min": float(np.min(higher))},
               "value": rendered.value.tolist(), "standard_error": rendered.standard_error.tolist(),
               "two_bounces": two_bounce.tolist(), "direct": rendered.cumulative[0].tolist(),
               "nominal": {}, "fitted": {}}
        if surface.kind == "heightfield":
            row["rms_slope_angle_deg"] = rms_slope_angle(surface.sigma)
        args = (geometries["theta_i"], 0.0, geometries["theta_r"], geometries["delta_phi"])
        for model, params in nominal_parameters(surface).items():
            row["nominal"][model] = differences(gonio.brdf(model, *args, **params), rendered, geometries)
        if surface.kind == "vgrooves":  # the two-bounce render is the exact model: a check
            exact = gonio.brdf("oren-nayar-exact", *args, rho=surface.rho, sigma=surface.sigma)
            z = (rendered.cumulative[1] - exact) / rendered.cumulative_error[1]
            row["two_bounce_render_vs_exact_rms_z"] = float(np.sqrt(np.mean(z**2)))
        for model in FIT_MODELS:
            row["fitted"][model] = fit(model, rendered, geometries)
        rows.append(row)
        nominal = "; ".join(f"{m} rms {v['all']['rms']:.2%}" for m, v in row["nominal"].items())
        print(f"{label}: {paths} paths x {rendered.value.size} geometries in {seconds:.0f} s "
              f"(MC error median {row['mc_relative_error']['median']:.2%}); {nominal}", flush=True)
    return rows


def albedo_orders() -> list[dict]:
    """Directional-hemispherical reflectance at theta_i = 45 deg split by scattering order."""
    rows = []
    kinds = [("vgrooves", lambda s, r: VGrooveField(s, r)), ("heightfield", lambda s, r: HeightField(s, r))]
    for kind, make in kinds:
        for sigma in SIGMAS:
            for rho in ALBEDO_RHOS:
                albedo = render_albedo(make(sigma, rho), 45.0, paths=ALBEDO_PATHS, seed=2, workers=WORKERS)
                rows.append({"kind": kind, "sigma": sigma, "rho": rho, "albedo": albedo.value,
                             "error": albedo.standard_error, "orders": albedo.orders.tolist(),
                             "order_errors": albedo.order_error.tolist()})
    for psi, coverage in PITS:
        for rho in ALBEDO_RHOS:
            albedo = render_albedo(PittedPlane(psi, coverage, rho), 45.0, paths=ALBEDO_PATHS, seed=2, workers=WORKERS)
            rows.append({"kind": "pits", "psi": psi, "coverage": coverage, "rho": rho, "albedo": albedo.value,
                         "error": albedo.standard_error, "orders": albedo.orders.tolist(),
                         "order_errors": albedo.order_error.tolist()})
    print(f"albedo by scattering order: {len(rows)} surfaces", flush=True)
    return rows


def fig10_curves() -> dict:
    """Plane of incidence at theta_i = 75 deg (Fig 10) and pits at theta_i = 60 deg."""
    views = np.arange(-85.0, 86.0, 5.0)
    theta_r, phi_r = np.abs(views), np.where(views >= 0, 0.0, 180.0)
    curves = {"views": views.tolist(), "grooves": {}, "pits": {}}
    for sigma in SIGMAS:
        entry = {}
        for kind, surface in (("vgrooves", VGrooveField(sigma, RHO)), ("heightfield", HeightField(sigma, RHO))):
            r = render(surface, 75.0, 0.0, theta_r, phi_r, paths=FIG10_PATHS, seed=3, workers=WORKERS)
            entry[kind] = {"value": r.value.tolist(), "error": r.standard_error.tolist(),
                           "direct": r.cumulative[0].tolist()}
        for model in ON_MODELS:
            entry[model] = gonio.brdf(model, 75.0, 0.0, theta_r, phi_r, rho=RHO, sigma=sigma).tolist()
        curves["grooves"][f"{sigma:g}"] = entry
    for psi, coverage in PITS:
        r = render(PittedPlane(psi, coverage, RHO), 60.0, 0.0, theta_r, phi_r, paths=FIG10_PATHS, seed=3,
                   workers=WORKERS)
        curves["pits"][f"{psi:g},{coverage:g}"] = {
            "value": r.value.tolist(), "error": r.standard_error.tolist(),
            "pitted": gonio.brdf("pitted", 60.0, 0.0, theta_r, phi_r, rho=RHO, psi=psi, coverage=coverage).tolist()}
    print("in-plane curves done", flush=True)
    return curves


def speed() -> dict:
    """Paths per second of the kernel per kind (one thread) against the numpy Monte Carlo
    of Koenderink et al. section 4.1 (single scattering, gonio.models.pitted.shallow), in
    this run.  Table build times and errors: benchmarks/surfaces_tables.py."""
    from gonio.models.pitted.shallow import monte_carlo_brdf

    out = {"kernel_paths_per_second": {}}
    start = time.perf_counter()
    monte_carlo_brdf(60.0, 45.0, 150.0, rho=RHO, psi=60.0, samples=1_000_000, seed=0)
    reference = 1_000_000 / (time.perf_counter() - start)
    out["reference_numpy_mc_samples_per_second"] = reference
    for label, surface in (("vgrooves", VGrooveField(30.0, RHO)), ("heightfield", HeightField(30.0, RHO)),
                           ("pits", PittedPlane(60.0, 1.0, RHO))):
        render(surface, 60.0, 0.0, 45.0, 150.0, paths=1000)  # compiled, realised
        start = time.perf_counter()
        rendered = render(surface, 60.0, 0.0, 45.0, 150.0, paths=1_000_000)
        rate = 1_000_000 / (time.perf_counter() - start)
        out["kernel_paths_per_second"][label] = {"paths_per_second": rate, "ratio_to_reference": rate / reference,
                                                 "rays_per_path": float(rendered.segments)}
    print(f"speed: {out['kernel_paths_per_second']}", flush=True)
    return out


def charts(curves: dict, rows: list[dict]) -> None:
    views = np.array(curves["views"])
    figure = Figure(figsize=(11, 8))
    styles = {"oren-nayar-exact": ("k", "-"), "oren-nayar": ("tab:blue", "--"), "oren-nayar-qualitative": ("tab:green", ":")}
    for k, (sigma, entry) in enumerate(curves["grooves"].items()):
        ax = figure.add_subplot(2, 2, k + 1)
        cos_i = np.cos(np.radians(75.0))  # radiance per unit E0, as Fig 10 plots it
        for kind, colour in (("vgrooves", "tab:red"), ("heightfield", "tab:purple")):
            value = np.array(entry[kind]["value"]) * cos_i
            ax.errorbar(views, value, yerr=2 * np.array(entry[kind]["error"]) * cos_i, fmt="o", ms=3, color=colour,
                        label=f"rendered {kind}, all bounces")
        ax.plot(views, np.array(entry["vgrooves"]["direct"]) * cos_i, color="tab:red", lw=0.8,
                label="rendered vgrooves, direct light")
        for model, (colour, dash) in styles.items():
            ax.plot(views, np.array(entry[model]) * cos_i, color=colour, ls=dash, label=model)
        ax.set_title(f"sigma = {sigma} deg, rho = {RHO}, theta_i = 75 deg")
        ax.set_xlabel("signed viewing angle [deg] (positive: source side)")
        ax.set_ylabel("radiance / E0 [1/sr]")
        if k == 0:
            ax.legend(fontsize=7)
    figure.subplots_adjust(hspace=0.35, wspace=0.25, left=0.07, right=0.98, top=0.95, bottom=0.07)
    figure.savefig(OUT / "surfaces_fig10.png", dpi=110)

    figure = Figure(figsize=(11, 4))
    ax = figure.add_subplot(1, 1, 1)
    for k, (key, entry) in enumerate(curves["pits"].items()):
        colour = f"C{k}"
        psi, coverage = key.split(",")
        ax.errorbar(views, entry["value"], yerr=2 * np.array(entry["error"]), fmt="o", ms=3, color=colour,
                    label=f"rendered pits psi={psi}, coverage={coverage}")
        ax.plot(views, entry["pitted"], color=colour, label="pitted model (lines)" if k == 0 else None)
    ax.set_xlabel("signed viewing angle [deg] (positive: source side)")
    ax.set_ylabel("BRDF [1/sr]")
    ax.set_title(f"pitted planes, theta_i = 60 deg, rho = {RHO}: rendered (2 sigma bars) and the closed form")
    ax.legend(fontsize=7, ncol=2)
    figure.subplots_adjust(left=0.07, right=0.98, top=0.9, bottom=0.13)
    figure.savefig(OUT / "surfaces_pits.png", dpi=110)

    figure = Figure(figsize=(11, 4))
    for k, kind in enumerate(("vgrooves", "heightfield")):
        ax = figure.add_subplot(1, 2, k + 1)
        chosen = [r for r in rows if r["kind"] == kind]
        sigmas = [r["parameters"]["sigma"] for r in chosen]
        for model, (colour, dash) in styles.items():
            ax.plot(sigmas, [100 * r["nominal"][model]["theta <= 80 deg"]["rms"] for r in chosen], color=colour,
                    ls=dash, marker="o", label=f"{model} at the surface's sigma")
            ax.plot(sigmas, [100 * r["fitted"][model.replace("-exact", "-tabulated")]["theta <= 80 deg"]["rms"]
                             for r in chosen], color=colour, ls=dash, marker="x", alpha=0.6,
                    label=f"{model} fitted")
        ax.plot(sigmas, [100 * r["mc_relative_error"]["median"] for r in chosen], color="grey", lw=0.8,
                label="Monte Carlo error (median)")
        ax.set_xlabel("sigma [deg]")
        ax.set_ylabel("rms relative difference, theta <= 80 deg [%]")
        ax.set_title(f"rendered {kind}, rho = {RHO}, all bounces")
        if k == 0:
            ax.legend(fontsize=7)
    figure.subplots_adjust(wspace=0.25, left=0.07, right=0.98, top=0.9, bottom=0.13)
    figure.savefig(OUT / "surfaces_summary.png", dpi=110)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %" if abs(x) >= 0.001 else f"{100 * x:.2f} %"


def markdown(payload: dict) -> str:
    rows = payload["comparison"]
    lines = [
        "# Rendered surfaces against the papers' models: the study",
        "",
        "Generated by `python benchmarks/surfaces_study.py` (data: `docs/benchmarks/surfaces.json`; charts "
        "`surfaces_fig10.png`, `surfaces_pits.png`, `surfaces_summary.png`); do not edit by hand.  What the "
        "surfaces are and how they are rendered: docs/surfaces.md.",
        "",
        f"Every surface is rendered with all bounces at rho = {RHO} on {payload['n_geometries']} geometries: "
        "in the plane of incidence (theta_i = 0, 30, 60, 75, 85 deg, signed views -85 ... 85 deg in steps of "
        "10), out of it (theta_i = 30, 60, 80, theta_r = 20, 50, 80, dphi = 45, 90, 135 deg) and a grazing set "
        "(polar angles 85-89 deg).  Relative difference = model / rendered - 1; 'theta <= 80 deg' leaves out "
        "the geometries with a polar angle beyond 80 deg, 'grazing' is those.",
        "",
        "## Monte Carlo errors of the renders",
        "",
        "| surface | paths per geometry | relative standard error, median / max | bounces beyond two, share of the BRDF: median / max |",
        "|---|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['surface']} | {r['paths']} | {_pct(r['mc_relative_error']['median'])} / "
                     f"{_pct(r['mc_relative_error']['max'])} | {_pct(r['beyond_two_bounces']['median'])} / "
                     f"{_pct(r['beyond_two_bounces']['max'])} |")
    checks = [r for r in rows if "two_bounce_render_vs_exact_rms_z" in r]
    lines += ["", "Check: the V-groove field rendered with two bounces against `oren-nayar-exact` (the same "
              "surface, the same truncation), rms of (render - exact)/error: "
              + ", ".join(f"{r['parameters']['sigma']:g} deg: {r['two_bounce_render_vs_exact_rms_z']:.2f}"
                          for r in checks) + " (1 is agreement within the Monte Carlo error).", ""]
    lines += ["## The models at the surfaces' own parameters", "",
              "| surface | model | rms (all) | max (all) | rms theta <= 80 | max theta <= 80 | rms in plane | "
              "rms out of plane | max grazing (at theta_i, theta_r, dphi) | rms of z |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        for model, d in r["nominal"].items():
            g = d["grazing (>= 80 deg)"]
            lines.append(
                f"| {r['surface']} | `{model}` | {_pct(d['all']['rms'])} | {_pct(d['all']['signed_max'])} | "
                f"{_pct(d['theta <= 80 deg']['rms'])} | {_pct(d['theta <= 80 deg']['signed_max'])} | "
                f"{_pct(d['in-plane']['rms'])} | {_pct(d['out-of-plane']['rms'])} | {_pct(g['signed_max'])} at "
                f"({', '.join(f'{x:g}' for x in g['worst_geometry'])}) | {d['all']['rms_z']:.1f} |")
    lines += ["", "## The models fitted to the renders", "",
              "Least squares on the relative differences at polar angles <= 80 deg, every parameter free "
              "(`oren-nayar-tabulated` stands for the exact model); the differences are then reported on every "
              "geometry.", "",
              "| surface | model | fitted parameters | rms (all) | max (all) | rms theta <= 80 | max theta <= 80 |",
              "|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        for model, d in r["fitted"].items():
            params = ", ".join(f"{k} {v:.3g}" for k, v in d["parameters"].items())
            lines.append(f"| {r['surface']} | `{model}` | {params} | {_pct(d['all']['rms'])} | "
                         f"{_pct(d['all']['signed_max'])} | {_pct(d['theta <= 80 deg']['rms'])} | "
                         f"{_pct(d['theta <= 80 deg']['signed_max'])} |")
    lines += ["", "## What the bounces beyond two add", "",
              f"Directional-hemispherical reflectance at theta_i = 45 deg ({ALBEDO_PATHS} paths each), and the "
              "share of it carried by the third and later scattering events.", "",
              "| surface | rho | reflectance | share of bounces >= 3 |", "|---|---:|---:|---:|"]
    for a in payload["albedo"]:
        name = (f"{a['kind']} sigma={a['sigma']:g}" if "sigma" in a else
                f"pits psi={a['psi']:g} coverage={a['coverage']:g}")
        share = a["orders"][2] / a["albedo"] if a["albedo"] > 0 else 0.0
        lines.append(f"| {name} | {a['rho']:g} | {a['albedo']:.4f} +- {a['error']:.4f} | {_pct(share)} |")
    s = payload["speed"]
    lines += ["", "## Speed", "",
              f"Kernel, one thread, 1e6 paths at theta_i = 60, theta_r = 45 deg, dphi = 150 deg; reference: the numpy "
              f"Monte Carlo of Koenderink et al. section 4.1 (single scattering only) in the same run, "
              f"{s['reference_numpy_mc_samples_per_second']:.3g} samples/s.", "",
              "| kind | paths/s | ratio to the reference | rays (or cells crossed) per path |", "|---|---:|---:|---:|"]
    for kind, entry in s["kernel_paths_per_second"].items():
        lines.append(f"| {kind} | {entry['paths_per_second']:.3g} | {entry['ratio_to_reference']:.2f} | "
                     f"{entry['rays_per_path']:.1f} |")
    lines += ["", "Table builds, their node errors and what a fit sees of them: `python benchmarks/surfaces_tables.py` "
              "(docs/surfaces.md, \"Tables\")."]
    lines += ["", f"Study total: {payload['seconds'] / 60:.1f} min wall, {payload['cpu_seconds'] / 60:.1f} min CPU.", ""]
    return "\n".join(lines)


def main() -> None:
    if "--charts" in sys.argv[1:]:
        payload = json.loads((OUT / "surfaces.json").read_text())
        charts(payload["fig10"], payload["comparison"])
        (ROOT / "docs" / "surfaces-study.md").write_text(markdown(payload))
        return
    start, cpu = time.perf_counter(), time.process_time()
    geometries = study_geometries()
    payload = {"machine": machine(), "rho": RHO, "n_geometries": int(geometries["theta_i"].size),
               "geometries": {k: v.tolist() for k, v in geometries.items()}}
    payload["speed"] = speed()
    payload["comparison"] = compare(geometries)
    payload["albedo"] = albedo_orders()
    curves = fig10_curves()
    payload["fig10"] = curves
    payload["seconds"], payload["cpu_seconds"] = time.perf_counter() - start, time.process_time() - cpu
    write_json("surfaces", payload)
    OFFSETS_FILE.write_text(json.dumps(offsets_from_study(payload), indent=1) + "\n")  # the fits' statements
    charts(curves, payload["comparison"])
    (ROOT / "docs" / "surfaces-study.md").write_text(markdown(payload))
    print(f"done in {payload['seconds'] / 60:.1f} min ({payload['cpu_seconds'] / 60:.1f} min CPU)")


if __name__ == "__main__":
    main()

"""Photometric stereo under a rough model against Lambertian least squares, on shapes
rendered independently of the model inverted (Oren & Nayar section 6.3, Figs 26-27).

Truths, each a sphere of SIZE pixels across under four sources at 30 deg from the viewer,
a quarter turn apart:

- the exact V-cavity model (``oren-nayar-exact``, the quadrature of eq 31) at sigma 20,
  30, 40 deg, rho 0.8, inverted with the tabulated model at the true parameters;
- rendered micro-surfaces (``gonio.surfaces``: V-grooves with every bounce traced, a
  Gaussian height field), which no formula wrote, inverted with ``oren-nayar-tabulated``
  fitted (MCMC, ``gonio.fitting.fit``) to 1 %-noise BRDF values of the surface at 210
  geometries in and out of the plane; the posterior draws' scatter enters each pixel's
  uncertainty.

Gaussian noise of NOISE of the brightest value is added (SEEDS seeds per truth) and stated
to both methods. Scored over pixels lit by at least three sources: the mean angular error
of each method, its ratio (the target: rough at most half of Lambert's at sigma >= 20 deg)
and the fraction of pixels whose true normal lies in its 95 % region (the target: 0.93 to
0.97), with the time of each method as a ratio to Lambert's in the same run.

Then the paper's own experiment (section 6.3, Figs 26-27): a vertical cylinder (the vase)
of the exact model at sigma 40 deg, rho 0.7, two sources at -10 and +10 deg, the albedo
known and the normals held in the horizontal plane, inverted with Lambert and with the
rough model; the heights integrated along the middle row against the true profile.

Writes docs/benchmarks/photometric_stereo.json and photometric_stereo.png. Run:
``python benchmarks/photometric_stereo.py`` (about 4 minutes; the surface tables are
rendered on first use and cached).
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from _common import OUT, machine, write_json

import gonio
from gonio import vision
from gonio.export import material_of
from gonio.fitting import Dataset, fit

SIZE = 81
LIGHTS = ((30.0, 0.0), (30.0, 90.0), (30.0, 180.0), (30.0, 270.0))
NOISE = 0.01
SEEDS = range(5)
EXACT = tuple({"sigma": s, "rho": 0.8} for s in (20.0, 30.0, 40.0))
SURFACES = ("kind=vgrooves,sigma=30,rho=0.9", "kind=heightfield,sigma=20,rho=0.8")
VASE = {"sigma": 40.0, "rho": 0.7, "lights": ((10.0, 180.0), (10.0, 0.0))}


def exact_brdf(sigma: float, rho: float):
    return lambda ti, pi, tr, pr: gonio.brdf("oren-nayar-exact", ti, pi, tr, pr, sigma=sigma, rho=rho)


def surface_brdf(spec: str):
    from gonio.surfaces.spec import parse_surface_spec
    from gonio.surfaces.table import TabulatedSurface

    return TabulatedSurface(parse_surface_spec(spec))


def fitted_material(brdf, seed: int = 0):
    """``oren-nayar-tabulated`` fitted by MCMC to 1 %-noise values of ``brdf`` at 210
    geometries (theta_i 0-75, theta_r 0-80, five azimuths)."""
    ti, tr, pr = (a.ravel() for a in np.meshgrid([0.0, 20.0, 40.0, 60.0, 75.0], np.arange(0.0, 81.0, 10.0),
                                                  [0.0, 45.0, 90.0, 135.0, 180.0], indexing="ij"))
    keep = ~((ti == 0.0) & (pr > 0.0))  # at normal incidence the azimuth is undefined
    ti, tr, pr = ti[keep], tr[keep], pr[keep]
    value = np.asarray(brdf(ti, 0.0, tr, pr), float)
    noisy = value * (1.0 + NOISE * np.random.default_rng(seed).standard_normal(value.size))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = fit(Dataset(ti, 0.0, tr, pr, noisy, NOISE * value), "oren-nayar-tabulated", mcmc=True, seed=seed)
    return material_of(result, max_draws=20), {k: float(v) for k, v in result.best_values().items()}


def render_images(brdf, normals, mask, lights) -> np.ndarray:
    return np.stack([vision.render(brdf, normals, mask, vision.direction(*light)) for light in lights])


def score(result, normals, evaluated) -> dict:
    error = vision.angular_error(result.normals, normals)[evaluated]
    return {"mean_error_deg": float(np.mean(error)), "median_error_deg": float(np.median(error)),
            "coverage": float(np.mean(result.covers(normals)[evaluated])),
            "median_cone_deg": float(np.median(result.cone_deg()[evaluated]))}


def sphere_case(name: str, brdf, model, seeds=SEEDS) -> dict:
    """Both methods on noisy images of a sphere of ``brdf``, inverting ``model``."""
    normals, mask = vision.sphere_normals(SIZE)
    clean = render_images(brdf, normals, mask, LIGHTS)
    evaluated = mask & (np.sum(np.nan_to_num(clean) > 0, axis=0) >= 3)
    sd = NOISE * float(np.nanmax(clean))
    rows = []
    for seed in seeds:
        images = clean + np.random.default_rng(seed).normal(0.0, sd, clean.shape)
        start = time.perf_counter()
        lambert = vision.photometric_stereo(images, LIGHTS, None, mask, noise_sd=sd)
        middle = time.perf_counter()
        rough = vision.photometric_stereo(images, LIGHTS, model, mask, noise_sd=sd)
        end = time.perf_counter()
        rows.append({"seed": seed, "lambert": score(lambert, normals, evaluated), "rough": score(rough, normals, evaluated),
                     "rough_time_over_lambert": (end - middle) / (middle - start)})
        print(f"{name} seed {seed}: Lambert {rows[-1]['lambert']['mean_error_deg']:.2f} deg, rough "
              f"{rows[-1]['rough']['mean_error_deg']:.2f} deg, coverage {rows[-1]['rough']['coverage']:.3f}", flush=True)
    return {"truth": name, "pixels": int(evaluated.sum()), "rows": rows, **summarise(rows)}


def summarise(rows: list[dict]) -> dict:
    mean = {m: float(np.mean([r[m]["mean_error_deg"] for r in rows])) for m in ("lambert", "rough")}
    return {"lambert_mean_error_deg": mean["lambert"], "rough_mean_error_deg": mean["rough"],
            "rough_over_lambert": mean["rough"] / mean["lambert"],
            "rough_coverage": float(np.mean([r["rough"]["coverage"] for r in rows])),
            "lambert_coverage": float(np.mean([r["lambert"]["coverage"] for r in rows])),
            "rough_time_over_lambert": float(np.median([r["rough_time_over_lambert"] for r in rows]))}


def vase_case() -> dict:
    """The paper's Figs 26-27: a cylinder, two sources at -10/+10 deg, known albedo."""
    normals, mask = vision.cylinder_normals(SIZE)
    brdf = exact_brdf(VASE["sigma"], VASE["rho"])
    clean = render_images(brdf, normals, mask, VASE["lights"])
    sd = NOISE * float(np.nanmax(clean))
    images = clean + np.random.default_rng(0).normal(0.0, sd, clean.shape)
    lambert = vision.lambert_brdf(VASE["rho"])
    model = material_of(f"oren-nayar-tabulated:sigma={VASE['sigma']},rho={VASE['rho']}")
    options = {"noise_sd": sd, "albedo_known": True, "in_plane_of": (0.0, 1.0, 0.0)}
    results = {name: vision.photometric_stereo(images, VASE["lights"], m, mask, **options)
               for name, m in (("lambert", lambert), ("rough", model))}
    evaluated = mask & (np.sum(clean > 0, axis=0) >= 2)
    middle, spacing = SIZE // 2, 2.0 / (SIZE - 1)
    truth = vision.height_profile(np.where(mask[middle][:, None], normals[middle], np.nan), spacing)
    out = {"truth": f"cylinder of oren-nayar-exact sigma {VASE['sigma']:g} rho {VASE['rho']:g}",
           "lights_deg": VASE["lights"], "profile_true": truth.tolist()}
    for name, result in results.items():
        heights = vision.height_profile(result.normals[middle], spacing)
        out[name] = score(result, normals, evaluated) | {
            "profile": heights.tolist(), "profile_rms_error": float(np.sqrt(np.nanmean((heights - truth) ** 2)))}
    return out


def chart(cases: list[dict], vase: dict) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(14.0, 4.2))
    axes = fig.subplots(1, 3)
    names = [c["truth"].replace("surface:", "").replace("oren-nayar-exact ", "exact\n") for c in cases]
    x = np.arange(len(cases))
    axes[0].bar(x - 0.2, [c["lambert_mean_error_deg"] for c in cases], 0.4, label="Lambert least squares")
    axes[0].bar(x + 0.2, [c["rough_mean_error_deg"] for c in cases], 0.4, label="rough model")
    axes[0].set_ylabel("mean angular error [deg]")
    axes[1].plot(x, [c["rough_coverage"] for c in cases], "o", label="rough model")
    axes[1].axhspan(0.93, 0.97, color="tab:green", alpha=0.2, label="target 0.93-0.97")
    axes[1].set_ylim(0.5, 1.0)
    axes[1].set_ylabel("fraction of true normals in the 95 % region")
    for ax in axes[:2]:
        ax.set_xticks(x, names, fontsize=7, rotation=20)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    grid = np.linspace(-1.0, 1.0, len(vase["profile_true"]))
    axes[2].plot(grid, vase["profile_true"], "k-", lw=2, label="true")
    for name in ("lambert", "rough"):
        axes[2].plot(grid, vase[name]["profile"], "--", label=f"{name} (rms {vase[name]['profile_rms_error']:.3f})")
    axes[2].set_xlabel("position across the cylinder [radius]")
    axes[2].set_ylabel("height [radius]")
    axes[2].set_title("Figs 26-27: sources at -10/+10 deg, albedo known", fontsize=9)
    axes[2].legend(fontsize=7)
    axes[2].grid(alpha=0.3)
    fig.suptitle(f"photometric stereo, sphere {SIZE} px, sources at 30 deg, noise {NOISE:.0%} of the brightest value")
    fig.tight_layout()
    fig.savefig(OUT / "photometric_stereo.png", dpi=110)


def main() -> None:
    started = time.perf_counter()
    cases = []
    for truth in EXACT:
        spec = f"oren-nayar-tabulated:sigma={truth['sigma']:g},rho={truth['rho']:g}"
        cases.append(sphere_case(f"oren-nayar-exact sigma {truth['sigma']:g}", exact_brdf(**truth),
                                 material_of(spec)) | {"inverted": spec})
    for spec in SURFACES:
        brdf = surface_brdf(spec)
        material, fitted = fitted_material(brdf)
        cases.append(sphere_case(f"surface:{spec}", brdf, material) | {"inverted": "oren-nayar-tabulated fitted",
                                                                         "fitted": fitted})
    vase = vase_case()
    record = {"machine": machine(), "size_px": SIZE, "lights_deg": LIGHTS, "noise_of_brightest": NOISE,
              "seeds": len(SEEDS), "cases": cases, "vase": vase, "seconds": time.perf_counter() - started}
    write_json("photometric_stereo", record)
    chart(cases, vase)
    for c in cases:
        print(f"{c['truth']}: Lambert {c['lambert_mean_error_deg']:.2f} deg, rough {c['rough_mean_error_deg']:.2f} deg "
              f"(ratio {c['rough_over_lambert']:.2f}), coverage {c['rough_coverage']:.3f}, "
              f"time x{c['rough_time_over_lambert']:.0f}")
    print(f"vase: Lambert {vase['lambert']['mean_error_deg']:.2f} deg, rough {vase['rough']['mean_error_deg']:.2f} deg; "
          f"profile rms {vase['lambert']['profile_rms_error']:.3f} vs {vase['rough']['profile_rms_error']:.3f}")


if __name__ == "__main__":
    main()

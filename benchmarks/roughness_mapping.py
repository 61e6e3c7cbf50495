"""Oren-Nayar sigma in renderers' roughness conventions: the mapping and its error.

For sigma = 0, 5, ..., 50 deg and two facet albedos, takes ``oren-nayar-exact`` (the
V-cavity model integrated numerically, rtol 1e-6) as the surface and measures, on the
cosine-weighted geometry set of :func:`gonio.models.roughness_conventions.match_geometry`
(10 x 10 polar nodes x 16 azimuth nodes = 1600 geometries):

* Mitsuba 0.6 ``roughdiffuse``: the closed-form alpha = sqrt(2) sigma [rad] with the full
  model (eq 33-35) and with ``useFastApprox`` (eq 36), and the alpha a fit prefers;
* EON (OpenPBR ``base_diffuse_roughness``) and Fujii's FON: the fitted r with the surface's
  albedo handed over unchanged, and with the albedo fitted too;
* Fujii's closed-form ratio r = B/A of his coefficients matched to full Oren-Nayar.

Each entry records the fitted value, the cosine-weighted relative rms BRDF difference and
the largest relative difference at polar angles <= 80 deg (and over all nodes).

Run:  .venv/bin/python benchmarks/roughness_mapping.py
Writes docs/benchmarks/roughness_mapping.json and docs/benchmarks/roughness_mapping.png.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.models.fujii import r_from_sigma_ratio  # noqa: E402
from gonio.models.roughness_conventions import (  # noqa: E402
    MAX_REL_THETA,
    RENDERERS,
    mapping_error,
    match_geometry,
    match_values,
    sigma_to_mitsuba_alpha,
)

SIGMAS = [float(s) for s in range(0, 51, 5)]
RHOS = [0.9, 0.5]
REFERENCE = "oren-nayar-exact"
ORDER, AZIMUTHS = 10, 8


def row_for(sigma: float, geometry: tuple[np.ndarray, ...]) -> dict:
    """Every mapping of one sigma, for each albedo."""
    out: dict = {"sigma": sigma, "mitsuba_alpha_closed_form": float(sigma_to_mitsuba_alpha(sigma)),
                 "rho": {}}
    for rho in RHOS:
        reference = gonio.brdf(REFERENCE, *geometry[:4], rho=rho, sigma=sigma)
        alpha = float(sigma_to_mitsuba_alpha(sigma))
        fujii_ratio = float(r_from_sigma_ratio(sigma, rho))
        entries = {
            "mitsuba_closed_form": mapping_error(reference, geometry, rho, "mitsuba-roughdiffuse", alpha),
            "mitsuba_fast_closed_form": mapping_error(reference, geometry, rho, "mitsuba-roughdiffuse-fast", alpha),
            "mitsuba": match_values(reference, geometry, rho, "mitsuba-roughdiffuse"),
            "mitsuba_fast": match_values(reference, geometry, rho, "mitsuba-roughdiffuse-fast"),
            "eon": match_values(reference, geometry, rho, "eon"),
            "eon_fit_albedo": match_values(reference, geometry, rho, "eon", fit_albedo=True),
            "fujii": match_values(reference, geometry, rho, "fujii-oren-nayar"),
            "fujii_fit_albedo": match_values(reference, geometry, rho, "fujii-oren-nayar", fit_albedo=True),
            "fujii_ratio_closed_form": mapping_error(reference, geometry, rho, "fujii-oren-nayar",
                                                     min(fujii_ratio, 1.0)),
            "eon_at_fujii_ratio": mapping_error(reference, geometry, rho, "eon", min(fujii_ratio, 1.0)),
        }
        out["rho"][str(rho)] = {key: match.as_dict() for key, match in entries.items()}
    return out


LABELS = {
    "mitsuba_closed_form": "Mitsuba roughdiffuse, alpha = sqrt(2) sigma (eq 33-35)",
    "mitsuba_fast_closed_form": "Mitsuba roughdiffuse fast, alpha = sqrt(2) sigma (eq 36)",
    "eon": "EON, fitted r, same rho",
    "eon_fit_albedo": "EON, fitted r and rho",
    "fujii": "FON, fitted r, same rho",
    "eon_at_fujii_ratio": "EON at Fujii's ratio r = B/A",
}


def chart(rows: list[dict], path: Path) -> None:
    sigma = np.array([row["sigma"] for row in rows])
    rho = str(RHOS[0])
    fig = Figure(figsize=(13, 9), layout="constrained")
    (ax_r, ax_alpha), (ax_rms, ax_max) = fig.subplots(2, 2)
    for key, style in (("eon", "-o"), ("eon_fit_albedo", "--o"), ("fujii", "-s"), ("fujii_fit_albedo", "--s")):
        ax_r.plot(sigma, [row["rho"][rho][key]["value"] for row in rows], style, ms=4,
                  label=key.replace("_fit_albedo", ", rho fitted").replace("fujii", "FON").replace("eon", "EON"))
    ax_r.plot(sigma, [row["rho"][rho]["fujii_ratio_closed_form"]["value"] for row in rows], ":", color="k",
              label="Fujii's ratio B/A (closed form)")
    ax_r.set(xlabel="Oren-Nayar sigma [deg]", ylabel="r (Fujii / EON / OpenPBR) [-]",
             title=f"fitted r against sigma (rho = {rho})")
    ax_r.legend(fontsize=8)
    ax_alpha.plot(sigma, [row["mitsuba_alpha_closed_form"] for row in rows], "-", color="k",
                  label="closed form sqrt(2) sigma [rad] (Mitsuba's own conversion)")
    ax_alpha.plot(sigma, [row["rho"][rho]["mitsuba"]["value"] for row in rows], "o", ms=4,
                  label="fitted, full model (eq 33-35)")
    ax_alpha.plot(sigma, [row["rho"][rho]["mitsuba_fast"]["value"] for row in rows], "s", ms=4,
                  label="fitted, useFastApprox (eq 36)")
    ax_alpha.set(xlabel="Oren-Nayar sigma [deg]", ylabel="Mitsuba alpha [-]",
                 title=f"Mitsuba 0.6 roughdiffuse alpha (rho = {rho})")
    ax_alpha.legend(fontsize=8)
    for index, (key, label) in enumerate(LABELS.items()):
        ax_rms.plot(sigma, [100 * row["rho"][rho][key]["rms"] for row in rows], "-o", ms=3, color=f"C{index}",
                    label=label)
        ax_max.plot(sigma, [100 * row["rho"][rho][key]["max_rel"] for row in rows], "-o", ms=3, color=f"C{index}",
                    label=label)
    ax_rms.set(xlabel="Oren-Nayar sigma [deg]", ylabel="cosine-weighted relative rms [%]",
               title=f"BRDF error against oren-nayar-exact, rms (rho = {rho})")
    ax_max.set(xlabel="Oren-Nayar sigma [deg]", ylabel="max |f / f_exact - 1| [%]",
               title=f"largest relative error, theta_i, theta_r <= {MAX_REL_THETA:g} deg (rho = {rho})")
    ax_rms.legend(fontsize=8)
    fig.savefig(path, dpi=100)


def main() -> None:
    start = time.perf_counter()
    geometry = match_geometry(ORDER, AZIMUTHS)
    rows = [row_for(sigma, geometry) for sigma in SIGMAS]
    elapsed = time.perf_counter() - start
    payload = {
        "description": ("Renderer roughness fitted to the Oren-Nayar V-cavity surface (oren-nayar-exact), and the "
                        "error of each mapping: rms = cosine-weighted relative rms BRDF difference over both "
                        f"hemispheres; max_rel = largest |f/f_ref - 1| at polar angles <= {MAX_REL_THETA:g} deg; "
                        "max_rel_all = over all nodes (nearest to grazing: 89.3 deg)."),
        "command": ".venv/bin/python benchmarks/roughness_mapping.py",
        "settings": {"reference": REFERENCE, "rho": RHOS, "sigma": SIGMAS, "order": ORDER, "azimuths": AZIMUTHS,
                     "geometries": int(geometry[0].size),
                     "weight": "cos(theta_i) cos(theta_r) d omega_i d omega_r, Gauss-Legendre in cos(theta) and dphi"},
        "renderers": {name: spec.description for name, spec in RENDERERS.items()},
        "rows": rows,
        "seconds": elapsed,
        "machine": machine(),
    }
    path = write_json("roughness_mapping", payload)
    chart(rows, OUT / "roughness_mapping.png")
    print(f"wrote {path} and roughness_mapping.png in {elapsed:.1f} s")
    header = f"{'sigma':>5} {'alpha':>7} {'alpha_fit':>9} {'rms_cf':>7} {'r_EON':>6} {'rms':>6} {'max80':>6} " \
             f"{'r_EON*':>6} {'rho*':>6} {'rms':>6} {'r_FON':>6} {'rms':>6}"
    for rho in RHOS:
        print(f"rho = {rho}\n{header}")
        for row in rows:
            e = row["rho"][str(rho)]
            print(f"{row['sigma']:5.0f} {row['mitsuba_alpha_closed_form']:7.4f} {e['mitsuba']['value']:9.4f} "
                  f"{e['mitsuba_closed_form']['rms']:7.4f} {e['eon']['value']:6.3f} {e['eon']['rms']:6.3f} "
                  f"{e['eon']['max_rel']:6.3f} {e['eon_fit_albedo']['value']:6.3f} {e['eon_fit_albedo']['rho']:6.3f} "
                  f"{e['eon_fit_albedo']['rms']:6.3f} {e['fujii']['value']:6.3f} {e['fujii']['rms']:6.3f}")


if __name__ == "__main__":
    main()

"""Pitted surfaces (Koenderink et al. 1999): closed form vs 1-D integral vs Monte Carlo.

Three families of geometries, each with its reference measured in the same run:

* ``pitted psi=90 in-plane``: hemispherical pits in the plane of incidence; reference the
  closed form of eq 26-29.
* ``pitted psi=90 off-plane``: hemispherical pits at random azimuths; reference the 1-D
  integral of eq 21-25 at 256 nodes per panel.
* ``pitted psi=45``: shallow pits at random azimuths; reference the cap quadrature of
  gonio.models.pitted.quadrature at 128 nodes per panel.

Methods: the closed form of eq 26-29 (in-plane only), the general closed form of
gonio.models.pitted.closed_form (Stokes' theorem over the boundary arcs of the lit and
visible cavity: what the registered ``pitted`` model evaluates), the eq 21 integral and the
cap quadrature at several orders, and the Monte Carlo
estimator of section 4.1 at 1e2 ... 1e6 samples.  For each: time per BRDF evaluation
(vectorised over the geometries for the deterministic methods; one call per geometry for
Monte Carlo) and the RMS relative error over the geometries; Monte Carlo records also
carry the mean reported standard error, so one can see that the estimator's error bars
are honest.

Run:  python benchmarks/bench_pitted.py   (~1 min; writes docs/benchmarks/pitted.json/.png)
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, best_time, machine, write_json  # noqa: E402

import gonio  # noqa: E402

from gonio.models.pitted.hemispherical import in_plane_brdf, integral_brdf  # noqa: E402
from gonio.models.pitted.interreflection import diffuse_brdf  # noqa: E402
from gonio.models.pitted.model import single_scattering  # noqa: E402
from gonio.models.pitted.quadrature import DEFAULT_ORDER, single_scattering_factor  # noqa: E402
from gonio.models.pitted.shallow import monte_carlo_brdf  # noqa: E402

RHO = 0.8
N_GEOMETRIES = 200
N_MC_GEOMETRIES = 12
MC_SAMPLES = (100, 1_000, 10_000, 100_000, 1_000_000)
#: Geometries for timing the closed form (vectorised, so its per-call overhead is spread)
N_CLOSED_TIMING = 200_000


def quadrature_brdf(alpha, beta, eps, psi, order):
    """Pit BRDF [1/sr] via the cap quadrature (alpha, beta, eps, psi in deg)."""
    f1 = single_scattering_factor(np.radians(alpha), np.radians(beta), np.radians(eps), np.radians(psi), order)
    return RHO * f1 + diffuse_brdf(RHO, psi)


def closed_brdf(alpha, beta, eps, psi):
    """Pit BRDF [1/sr] with F1 in closed form (the model's default; angles in deg)."""
    f1 = single_scattering(np.radians(alpha), np.radians(beta), np.radians(eps), np.radians(psi))
    return RHO * f1 + diffuse_brdf(RHO, psi)


def eq21_brdf(alpha, beta, eps, order):
    single, multiple = integral_brdf(alpha, beta, eps, RHO, order=order)
    return single + multiple


def rms_relative(values, reference):
    return float(np.sqrt(np.mean(((np.asarray(values) - reference) / reference) ** 2)))


def record(family, method, seconds, error, reference, notes, **extra):
    return {"family": family, "method": method, "seconds_per_evaluation": float(seconds),
            "relative_error": float(error), "reference_method": reference, "notes": notes, **extra}


def geometries(family: str, rng: np.random.Generator):
    alpha = rng.uniform(0.0, 80.0, N_GEOMETRIES)
    beta = rng.uniform(0.0, 80.0, N_GEOMETRIES)
    if family.endswith("in-plane"):
        eps = np.where(rng.random(N_GEOMETRIES) < 0.5, 0.0, 180.0)
    else:
        eps = rng.uniform(-180.0, 180.0, N_GEOMETRIES)
    return alpha, beta, eps


def run_family(family: str, psi: float, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    alpha, beta, eps = geometries(family, rng)
    n = len(alpha)
    records = []
    if family.endswith("in-plane"):
        signed = np.where(eps == 0.0, beta, -beta)
        reference = in_plane_brdf(alpha, signed, RHO)
        ref_name = "closed form eq 26-29"
        ref_time = best_time(lambda: in_plane_brdf(alpha, signed, RHO)) / n
        records.append(record(family, "closed form eq 26-29", ref_time, 0.0, ref_name, "reference"))
    elif psi == 90.0:
        reference = eq21_brdf(alpha, beta, eps, 256)
        ref_name = "eq 21 integral, 256 nodes/panel"
        ref_time = best_time(lambda: eq21_brdf(alpha, beta, eps, 256), repeats=2) / n
        records.append(record(family, "eq 21 integral n=256", ref_time, 0.0, ref_name, "reference"))
    else:
        reference = quadrature_brdf(alpha, beta, eps, psi, 128)
        ref_name = "cap quadrature, 128 nodes/panel"
        ref_time = best_time(lambda: quadrature_brdf(alpha, beta, eps, psi, 128), repeats=2) / n
        records.append(record(family, "cap quadrature n=128", ref_time, 0.0, ref_name, "reference"))

    if psi == 90.0:
        for order in (8, 16, 32, 64):
            t = best_time(lambda: eq21_brdf(alpha, beta, eps, order)) / n
            err = rms_relative(eq21_brdf(alpha, beta, eps, order), reference)
            records.append(record(family, f"eq 21 integral n={order}", t, err, ref_name,
                                  f"time ratio to reference {t / ref_time:.3g}", time_ratio_to_reference=t / ref_time))
    tiled = tuple(np.resize(a, N_CLOSED_TIMING) for a in (alpha, beta, eps))
    t = best_time(lambda: closed_brdf(*tiled, psi)) / N_CLOSED_TIMING
    err = rms_relative(closed_brdf(alpha, beta, eps, psi), reference)
    records.append(record(family, "closed form, boundary arcs (model default)", t, err, ref_name,
                          f"time ratio to reference {t / ref_time:.3g}; timed on {N_CLOSED_TIMING} geometries",
                          time_ratio_to_reference=t / ref_time))
    for order in (4, 8, 12, DEFAULT_ORDER, 24, 32):
        t = best_time(lambda: quadrature_brdf(alpha, beta, eps, psi, order)) / n
        err = rms_relative(quadrature_brdf(alpha, beta, eps, psi, order), reference)
        label = f"cap quadrature n={order}"
        records.append(record(family, label, t, err, ref_name, f"time ratio to reference {t / ref_time:.3g}",
                              time_ratio_to_reference=t / ref_time))
    subset = np.arange(min(N_MC_GEOMETRIES, n))
    for samples in MC_SAMPLES:
        values, errors, elapsed = [], [], 0.0
        for k in subset:
            start = time.perf_counter()
            est = monte_carlo_brdf(alpha[k], beta[k], eps[k], rho=RHO, psi=psi, samples=samples, seed=int(k))
            elapsed += time.perf_counter() - start
            values.append(est.value)
            errors.append(est.standard_error / est.value)
        t = elapsed / len(subset)
        err = rms_relative(values, reference[subset])
        reported = float(np.sqrt(np.mean(np.square(errors))))
        records.append(record(
            family, f"Monte Carlo {samples:.0e}", t, err, ref_name,
            f"{len(subset)} geometries; RMS reported standard error {reported:.2g}; "
            f"time ratio to reference {t / ref_time:.3g}",
            reported_relative_standard_error=reported, time_ratio_to_reference=t / ref_time, samples=samples,
        ))
    return records


def chart(records: list[dict], path: Path) -> None:
    families = sorted({r["family"] for r in records})
    fig = Figure(figsize=(5.2 * len(families), 4.4), layout="constrained")
    axes = fig.subplots(1, len(families), squeeze=False)[0]
    styles = {"closed form, boundary": ("C3", "D"), "eq 21": ("C0", "o"), "cap": ("C1", "s"), "Monte": ("C2", "^")}
    for ax, family in zip(axes, families):
        reference = [r for r in records if r["family"] == family and r["notes"] == "reference"]
        for r in reference:
            ax.loglog(r["seconds_per_evaluation"], 1e-16, "k*", ms=10, label=f"reference: {r['method']}")
        for key, (color, marker) in styles.items():
            rows = [r for r in records if r["family"] == family and r["method"].startswith(key)
                    and r["notes"] != "reference"]
            if not rows:
                continue
            x = [r["seconds_per_evaluation"] for r in rows]
            y = [max(r["relative_error"], 1e-16) for r in rows]
            ax.loglog(x, y, marker=marker, color=color, ls="-" if len(rows) > 1 else "", label=key)
            for r, xi, yi in zip(rows, x, y):
                tokens = r["method"].split()
                label = next((tok for tok in tokens if tok.startswith("n=")), "" if key.startswith("closed") else tokens[-1])
                ax.annotate(label, (xi, yi), fontsize=6,
                            xytext=(3, 2), textcoords="offset points")
        ax.set_title(family, fontsize=10)
        ax.set_xlabel("time per BRDF evaluation [s]")
        ax.set_ylabel("RMS relative error [-] (1e-16 = exact)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle(f"Pitted surfaces: closed forms, eq 21 integral, cap quadrature, Monte Carlo (rho = {RHO})")
    fig.savefig(path, dpi=110)


def model_speed(n: int = 1_000_000) -> dict[str, float]:
    """Evaluations/s of the registered ``pitted`` model (plain call, new psi every call,
    random geometries over the whole hemisphere) and of the cap quadrature it used before,
    measured in the same run on 2e4 of the geometries."""
    rng = np.random.default_rng(7)
    geometry = (rng.uniform(0, 90, n), rng.uniform(-180, 180, n), rng.uniform(0, 90, n), rng.uniform(-180, 180, n))
    psis = iter(np.linspace(30.0, 89.0, 1000))
    model = gonio.models.get("pitted")
    plain = best_time(lambda: model(*geometry, rho=RHO, psi=float(next(psis)), coverage=0.5), repeats=5) / n
    m = 20_000
    a, b, e = (np.radians(x[:m]) for x in (geometry[0], geometry[2], geometry[3] - geometry[1]))
    quadrature = best_time(lambda: single_scattering_factor(a, b, e, np.radians(60.0), DEFAULT_ORDER), repeats=3) / m
    return {"pitted plain call (closed form)": 1.0 / plain, "cap quadrature n=16 (F1 only)": 1.0 / quadrature,
            "speed_ratio_closed_form_vs_quadrature": quadrature / plain}


def main() -> None:
    start = time.perf_counter()
    records = []
    for seed, (family, psi) in enumerate(
        (("pitted psi=90 in-plane", 90.0), ("pitted psi=90 off-plane", 90.0), ("pitted psi=45", 45.0))
    ):
        records += run_family(family, psi, seed)
        print(f"{family}: done ({time.perf_counter() - start:.1f} s)", flush=True)
    for r in records:
        print(f"{r['family']:26s} {r['method']:44s} {r['seconds_per_evaluation']:.3e} s  err {r['relative_error']:.2e}")
    speed = model_speed()
    for key, value in speed.items():
        print(f"  {key}: {value:.3g}" + (" evaluations/s" if "ratio" not in key else ""))
    payload = {
        "benchmark": "pitted",
        "command": "python benchmarks/bench_pitted.py",
        "machine": machine(),
        "records": records,
        "rho": RHO,
        "n_geometries": N_GEOMETRIES,
        "n_monte_carlo_geometries": N_MC_GEOMETRIES,
        "quadrature_default_order": DEFAULT_ORDER,
        "model_speed": speed,
        "total_seconds": time.perf_counter() - start,
    }
    path = write_json("pitted", payload)
    chart(records, OUT / "pitted.png")
    print(f"wrote {path} and {OUT / 'pitted.png'} in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()

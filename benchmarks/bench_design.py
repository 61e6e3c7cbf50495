"""Instrument time against certainty: the expected front of designed and shipped protocols.

For the paper's plaster (``oren-nayar-tabulated``, true sigma = 30 deg, rho = 0.9; priors
sigma 10-45 deg, rho 0.5-1) every protocol's estimated instrument time (``gonio plan``:
the camera's characterisation, moves, settling, exposures, darks, the reference standard;
within 5 % of the emulated recordings) is set against the expected 95 % interval widths of
sigma and rho (the Laplace approximation at the truth: the inverse of the Fisher
information with the priors', for the realistic rig's 0.25 % relative noise per value, a
0.5 % calibration common to every value and the rig's alignment errors of 0.5 deg
marginalised; :func:`gonio.design.expected_widths`):

- the shipped in-plane protocols of Figs 16, 17 and 19 and thinned variants of Fig 16
  (every second view, one incidence of three); a protocol without a reference standard
  (Fig 17) has a free calibration factor, so its rho is undetermined,
- designs of ``gonio design`` (:func:`gonio.design.design`) at budgets from 260 s to 900 s,
  in the plane of incidence (over the rig's range, and with ``max_angle`` 75 deg), and
  with lamp azimuths 0, 45 and 90 deg.

Each point's time is the planned one, and the time each design took to compute is
recorded beside. The widths are expected ones; ``design_study.py`` measures them on
emulated recordings.

Run: ``python benchmarks/bench_design.py`` (about a minute); writes
``docs/benchmarks/design.json`` and ``design.png``.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from _common import OUT, ROOT, machine, write_json

from gonio import design as D
from gonio import protocols as P

MODEL = "oren-nayar-tabulated"
PRIORS = {"sigma": (10.0, 45.0), "rho": (0.5, 1.0)}
FIXED: dict[str, float] = {}
TRUTH = {"sigma": 30.0, "rho": 0.9}
BUDGETS = (260.0, 300.0, 435.0, 600.0, 900.0)
SHIPPED = ("oren-nayar-fig16-plaster.toml", "oren-nayar-fig17-sandpaper.toml", "oren-nayar-fig19-off-plane.toml")


#: The calibration's relative prior width of a protocol without a reference standard: free.
FREE = 1e3


def _row(name: str, kind: str, points, seconds: float, compute: float | None = None,
         calibrated: bool = True) -> dict:
    widths = D.expected_widths(MODEL, points, PRIORS, FIXED, calibration=D.DEFAULT_CALIBRATION if calibrated else FREE,
                               at=TRUTH)
    return {"name": name, "kind": kind, "points": len(points), "seconds": seconds, "width_sigma": widths["sigma"],
            "width_rho": widths["rho"], "design_seconds": compute}


def _protocol_row(name: str, protocol: P.Protocol) -> dict:
    plan = P.plan(protocol)
    return _row(name, "shipped" if "thinned" not in name else "thinned",
                [(p.theta_i, p.phi_i, p.view) for p in plan.points], plan.estimated_seconds,
                calibrated=protocol.reference is not None)


def _thinned(path: Path) -> list[tuple[str, P.Protocol]]:
    """Fig 16 with every second view, and with one incidence of three."""
    text = path.read_text()
    protocol = P.loads(text, source=str(path))
    every_second = text.replace("step = 5", "step = 10")
    out = []
    if every_second != text:
        out.append(("Fig 16, every second view (thinned)", P.loads(every_second, source="thinned")))
    one = dataclasses.replace(protocol, blocks=protocol.blocks[1:2])
    out.append(("Fig 16, theta_i = 45 only (thinned)", one))
    return out


def measure() -> list[dict]:
    rows = [_protocol_row(name.replace(".toml", ""), P.load(ROOT / "protocols" / name)) for name in SHIPPED]
    rows += [_protocol_row(name, protocol) for name, protocol in _thinned(ROOT / "protocols" / SHIPPED[0])]
    for azimuths, kind, options in (((0.0,), "design, plane of incidence", {}),
                                    ((0.0,), "design, plane of incidence, angles to 75 deg", {"max_angle": 75.0}),
                                    ((0.0, 45.0, 90.0), "design, azimuths 0/45/90", {})):
        for budget in BUDGETS:
            start = time.perf_counter()
            result = D.design(MODEL, PRIORS, budget, fixed=FIXED, azimuths=azimuths, **options)
            rows.append(_row(f"{kind}, {budget:g} s", kind, result.points, result.seconds,
                             time.perf_counter() - start))
    return rows


def chart(rows: list[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.2))
    for k, key in enumerate(("width_sigma", "width_rho")):
        ax = fig.add_subplot(1, 2, k + 1)
        for kind, marker in (("shipped", "s"), ("thinned", "v"), ("design, plane of incidence", "o"),
                             ("design, plane of incidence, angles to 75 deg", "D"), ("design, azimuths 0/45/90", "^")):
            chosen = [r for r in rows if r["kind"] == kind]
            ax.plot([r["seconds"] for r in chosen], [r[key] for r in chosen], marker=marker,
                    ls="-" if kind.startswith("design") else "none", label=kind)
        ax.set_xlabel("estimated instrument time [s] (gonio plan)")
        ax.set_ylabel(f"expected 95 % width of {key.split('_')[1]}" + (" [deg]" if key == "width_sigma" else " [-]"))
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    fig.suptitle("Instrument time against expected certainty: plaster (sigma 30 deg, rho 0.9), 0.25 % noise, "
                 "0.5 % calibration, alignment errors of 0.5 deg marginalised", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    rows = measure()
    for r in rows:
        extra = f"  (designed in {r['design_seconds']:.1f} s)" if r["design_seconds"] is not None else ""
        print(f"{r['name']:<45} {r['points']:4d} points {r['seconds']:7.0f} s  sigma {r['width_sigma']:.3f} deg  "
              f"rho {r['width_rho']:.4f}{extra}")
    write_json("design", {"model": MODEL, "priors": PRIORS, "fixed": FIXED, "truth": TRUTH,
                          "noise": D.DEFAULT_NOISE, "calibration": D.DEFAULT_CALIBRATION, "rows": rows,
                          "machine": machine()})
    chart(rows, OUT / "design.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

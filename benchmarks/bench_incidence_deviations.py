"""Is the stated covariance of the standard's irradiance per lamp angle true?

Under the calibration per incidence (docs/acquisition.md, "Calibration per incidence")
each value is divided by ``E_k``, the reference standard's irradiance at its lamp polar
angle, and brought back to the common level ``E_0``; the reduction states the covariance
of ``E_k / E_0 - 1`` between angles (``Reduced._incidence_deviations``) taking the ``E_k``
as independent, while in the recording readings at different angles share dark frames
and ``E_0``'s weights count only their independent components.  This measures the
reduction itself: the emulated rig (uniform beam, lamp monitor; truth ``E_k / E_0 = 1``)
reads a Lambertian standard at six lamp polar angles (10 to 60 deg, camera at -10 deg),
seed after seed, and the chi-square of the deviations against the stated covariance is
pooled over the seeds (five degrees of freedom each: the six deviations sum to 0 with
``E_0``'s weights).  Recorded: chi-square / dof with its expected spread, and per angle
the rms of the deviations against the stated standard deviation.

Writes docs/benchmarks/incidence_deviations.json.
Run: ``python benchmarks/bench_incidence_deviations.py`` (about 30 s; ``--seeds N``,
default 24).
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import machine, write_json  # noqa: E402

from gonio import acquisition  # noqa: E402
from tests.emulated_recording import STANDARD_ANGLES, record  # noqa: E402

SAMPLE = "oren-nayar:sigma=30,rho=0.9,ir_weight=1"
ANGLES = (10, 20, 30, 40, 50, 60)  # the lamp polar angles of STANDARD_ANGLES [deg]


def deviations(folder: Path, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``E_k / E_0 - 1`` of one seeded recording and their stated covariance."""
    reduced = acquisition.reduce_recording(record(folder, STANDARD_ANGLES, SAMPLE, seed))
    deviation = np.array([c.irradiance for c in reduced.incidences]) / reduced.reference_irradiance - 1.0
    return deviation, reduced._incidence_deviations()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=24)
    args = parser.parse_args()
    chi2, rows, stated = 0.0, [], []
    with tempfile.TemporaryDirectory() as root:
        for seed in range(args.seeds):
            deviation, covariance = deviations(Path(root) / f"seed{seed}", seed)
            chi2 += float(deviation[:-1] @ np.linalg.solve(covariance[:-1, :-1], deviation[:-1]))
            rows.append(deviation)
            stated.append(np.sqrt(np.diag(covariance)))
    dof = args.seeds * (len(ANGLES) - 1)
    rms = np.sqrt(np.mean(np.square(rows), axis=0))
    sd = np.sqrt(np.mean(np.square(stated), axis=0))
    payload = {
        "what": "E_k / E_0 - 1 of the reduction on the emulated rig (uniform beam, truth 0) against the covariance "
                "it states, pooled over seeds",
        "command": "python benchmarks/bench_incidence_deviations.py" + (f" --seeds {args.seeds}"
                                                                        if args.seeds != 24 else ""),
        "seeds": args.seeds, "angles_deg": list(ANGLES), "chi2": chi2, "dof": dof,
        "chi2_per_dof": chi2 / dof, "chi2_per_dof_expected_sd": math.sqrt(2.0 / dof),
        "per_angle": [{"theta_i": t, "rms_deviation": float(r), "stated_sd": float(s), "ratio": float(r / s)}
                      for t, r, s in zip(ANGLES, rms, sd)],
        "machine": machine(),
    }
    path = write_json("incidence_deviations", payload)
    print(f"chi-square / dof = {chi2 / dof:.3f} ({dof} dof, expected 1 +- {math.sqrt(2.0 / dof):.2f}); "
          + ", ".join(f"{t} deg {r / s:.2f}" for t, r, s in zip(ANGLES, rms, sd)) + f" (rms / stated); {path}")


if __name__ == "__main__":
    main()

"""benchmarks/curet_batch.py's page generator (docs/curet-all.md) on a tiny synthetic table.

No CUReT data and no fit: the table below has the structure of ``sample_table``'s records,
with made-up numbers, so that the page's rows, counts and flags can be checked by hand.
"""
from __future__ import annotations

import math

import pytest

from tests.conftest import benchmark_script

CANDIDATES = ["lambert", "oren-nayar-qualitative", "oren-nayar:ir_weight=1", "oren-nayar"]


@pytest.fixture(scope="module")
def script():
    return benchmark_script("curet_batch")


def _fit(verdict, redchi, parameters, converged=True, r_hat=1.004, ess=2500.0):
    return {"status": "ok", "verdict": verdict, "redchi": redchi, "converged": converged, "r_hat_max": r_hat,
            "ess_bulk_min": ess, "failure": "", "wall_seconds": 1.0,
            "parameters": {name: dict(zip(("median", "p2_5", "p97_5"), values)) for name, values in parameters.items()},
            "validity_bias_sd": {}}


def _table():
    plaster = {
        "number": 10, "name": "plaster_a", "noise_relative": 0.0364, "negative": 0,
        "chosen": "oren-nayar:ir_weight=1", "chosen_verdict": "inadequate", "chosen_adequate": False,
        "fits": {
            "lambert": _fit("inadequate", 39.2, {"rho": (0.838, 0.809, 0.866)}),
            "oren-nayar-qualitative": _fit("inadequate", 8.55, {"rho": (0.888, 0.874, 0.903),
                                                                 "sigma": (26.1, 24.2, 28.0)}),
            "oren-nayar:ir_weight=1": _fit("inadequate", 1.87, {"rho": (0.843, 0.837, 0.849),
                                                                 "sigma": (20.9, 20.2, 21.7)}),
            "oren-nayar": _fit("noise understated", 1.88, {"rho": (0.849, 0.839, 0.87), "sigma": (20.4, 18.9, 21.4),
                                                           "ir_weight": (0.873, 0.42, 0.995)},
                               converged=False, r_hat=1.03, ess=150.0),
        },
    }
    dark = {
        "number": 61, "name": "sample-61", "noise_relative": 0.08, "negative": 28,
        "chosen": "lambert", "chosen_verdict": "adequate", "chosen_adequate": True,
        "fits": {
            "lambert": _fit("adequate", 1.1, {"rho": (0.05, 0.048, 0.052)}),
            "oren-nayar-qualitative": _fit("adequate", 1.1, {"rho": (0.05, 0.048, 0.052),
                                                             "sigma": (3.0, 0.1, 12.0)}),
            "oren-nayar:ir_weight=1": _fit("adequate", 1.1, {"rho": (0.05, 0.048, 0.052),
                                                             "sigma": (2.0, 0.05, 11.0)}),
            "oren-nayar": {"status": "failed", "failure": "RuntimeError: no convergence", "parameters": {},
                           "verdict": None, "redchi": None},
        },
    }
    return [plaster, dark]


def _context(script, table):
    run = {"workers": 2, "fitted": 8, "wall_seconds": 12.0, "task_seconds_fitted": 20.0, "cpu_count": 2,
           "finished_utc": "2026-01-01T00:00:00Z", "load_average_1min": {"mean": 2.5, "max": 3.0, "n": 3}}
    return {"candidates": CANDIDATES, "summary": script.summarise(table, CANDIDATES), "mcmc": "the MCMC",
            "credit": "CUReT data: Dana et al. 1999", "run": run, "workers": None, "rhat_limit": 1.01}


def test_sample_rows_give_the_chosen_model_its_intervals_every_redchi_and_the_flags(script):
    page = script.markdown(_table(), _context(script, _table()))
    assert ("| 10 | plaster_a | 0.036 | oren-nayar (ir_weight=1) | inadequate | 0.843 [0.837, 0.849] | "
            "20.9 [20.2, 21.7] | 20.9 [20.2, 21.7] | 39.2 I / 8.55 I / 1.87 I / 1.88 N | "
            "oren-nayar: not converged, R-hat 1.030, ESS 150 |") in page
    # Lambert has no sigma; the reference model's sigma interval reaches 0 (within 5 % of its width)
    assert ("| 61 | sample-61 | 0.080 | lambert | adequate | 0.05 [0.048, 0.052] | - | "
            "2 [0.05, 11] (at lower bound) | 1.1 A / 1.1 A / 1.1 A / failed | "
            "oren-nayar: failed; 28 negative value(s), kept |") in page


def test_model_counts_and_failures_are_summed_over_samples(script):
    table = _table()
    summary = script.summarise(table, CANDIDATES)
    on = summary["per_model"]["oren-nayar"]
    assert (on["ok"], on["failed"], on["noise understated"], on["not_converged"], on["rhat_flagged"],
            on["ess_flagged"]) == (1, 1, 1, 1, 1, 1)
    assert summary["per_model"]["lambert"]["chosen"] == 1 and summary["per_model"]["lambert"]["adequate"] == 1
    assert summary["samples_with_an_adequate_fit"] == 1 and summary["samples_with_a_passing_fit"] == 2
    assert summary["failures"] == [(61, "oren-nayar", "RuntimeError: no convergence")]
    # sigma of the reference model on both samples: median of 20.9 and 2
    assert math.isclose(summary["sigma"]["reference"]["quantiles_10_25_50_75_90"][2], (20.9 + 2.0) / 2)
    assert summary["sigma"]["reference"]["at_lower_bound"] == 1
    page = script.markdown(table, _context(script, table))
    assert "| oren-nayar | 1 | 0 | 1 | 0 | 1 | 0 | 1.88 | 1 | 1 | 1 | - |" in page
    assert "* curet-61 x `oren-nayar`: RuntimeError: no convergence" in page
    assert "**8 fits** of 4 models on 2 samples: 7 finished, 1 failed." in page


def test_bound_notes_follow_curet_fits(script):
    assert script.bound_note({"p2_5": 0.01, "p97_5": 5.0}, (0.0, 90.0)) == "at lower bound"
    assert script.bound_note({"p2_5": 0.3, "p97_5": 0.999}, (0.0, 1.0)) == "at upper bound"
    assert script.bound_note({"p2_5": 0.05, "p97_5": 0.95}, (0.0, 1.0)) == "unconstrained"
    assert script.bound_note({"p2_5": 20.2, "p97_5": 21.7}, (0.0, 90.0)) == ""


def test_the_summary_says_first_when_no_candidate_is_adequate_anywhere(script):
    plaster = _table()[0]
    plaster["fits"]["oren-nayar"] = _fit("inadequate", 1.88, {"rho": (0.849, 0.839, 0.87)})
    for fit in plaster["fits"].values():
        fit.update(lack_of_fit_p=3e-42, alpha=0.001)
    plaster["fits"]["lambert"]["lack_of_fit_p"] = 2e-7  # the largest is quoted
    page = script.markdown([plaster], _context(script, [plaster]))
    summary = page.split("## Summary", 1)[1].lstrip().splitlines()
    assert summary[0].startswith("* **Adequate descriptions**: lambert 0 of 1;")
    assert "**No candidate describes any sample adequately**" in summary[0]
    assert "largest lack-of-fit p 2e-07, threshold 0.001" in summary[0]

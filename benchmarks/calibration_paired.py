"""Two runs of the coverage study on the same data, compared seed by seed: did a change of
the MCMC change the posterior?

``benchmarks/calibration.py`` draws every seed's truth and emulator noise from the seed
alone, so two of its runs at different commits fit the same recordings (to the rounding of
whatever else changed between them). This script pairs the coverage records of two
``calibration.json`` files by (arm, seed) and reports, per arm and parameter:

* whether the data are the same: the largest difference of the least-squares values in
  units of the earlier run's least-squares standard error (least squares does not depend
  on the sampler);
* the shift of the posterior median in units of the earlier posterior sd (mean, rms,
  largest) and the ratio of the posterior sds (median, 5th and 95th percentiles): the
  Monte Carlo error of the median of a Gaussian from N effective samples is
  sqrt(pi / 2) / sqrt(N) sd, so two chains of the same posterior differ by
  sqrt(pi / 2) sqrt(1 / N1 + 1 / N2) sd rms, the figure printed beside the shift (N: each
  record's smallest ESS over its parameters, n_walkers (n_steps - burn-in) / max tau, so
  the figure is an upper bound for a parameter that mixes faster); an sd from N effective
  samples has a relative error of 1 / sqrt(2 N), so the log of the ratio of two scatters
  by sqrt(1 / (2 N1) + 1 / (2 N2)) rms, likewise printed;
* how many seeds changed their verdict (the truth inside the 68 % or 95 % interval);
* the chain lengths (median steps) and the number of kept samples of both runs;
* for each run, the uniformity of the truth's position in the posterior two ways: the
  SBC rank histogram of calibration.py (the rank among 99 random draws, so with the
  draws' own scatter) and the histogram of Phi(-z), z = (median - truth) / sd, the
  probability integral transform of a Gaussian posterior, without that scatter (chi-square
  test over the same 10 bins and Kolmogorov-Smirnov test against U(0, 1)).

Writes docs/benchmarks/calibration_paired.json. Run:
``python benchmarks/calibration_paired.py --before dfa89fd`` (the earlier JSON from git) or
``--before PATH``; ``--after`` defaults to docs/benchmarks/calibration.json.
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, write_json  # noqa: E402

#: Where calibration.py writes its results (relative to the repository).
CALIBRATION_JSON = "docs/benchmarks/calibration.json"
PARAMETERS = ("rho", "sigma")


def load_calibration(source: str) -> dict[str, Any]:
    """A calibration.json from a file path (as given, or relative to the repository) or,
    if no such file exists, from a git revision.

    Raises
    ------
    ValueError
        ``source`` is neither a readable file nor a revision holding the JSON.
    """
    for path in (Path(source), ROOT / source):
        if path.is_file():
            return json.loads(path.read_text())
    try:
        text = subprocess.run(["git", "show", f"{source}:{CALIBRATION_JSON}"], cwd=ROOT, capture_output=True,
                              text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as error:
        raise ValueError(f"{source!r} is neither a file nor a git revision holding {CALIBRATION_JSON}") from error
    return json.loads(text)


#: Design entries two runs may differ in: what the comparison is about.
MAY_DIFFER = ("mcmc",)


def design_differences(before: Mapping[str, Any], after: Mapping[str, Any]) -> list[str]:
    """The design entries (protocols, noise, prior, SBC settings, candidates, ...) in which
    two calibration.json files differ, beyond :data:`MAY_DIFFER`: pairing their seeds would
    compare different studies."""
    keys = (set(before["design"]) | set(after["design"])) - set(MAY_DIFFER)
    return sorted(k for k in keys if before["design"].get(k) != after["design"].get(k))


def paired_records(before: Mapping[str, Any], after: Mapping[str, Any]) -> dict[str, list[tuple[dict, dict]]]:
    """Coverage records of both runs with the same arm and seed, by arm."""
    later = {(r["arm"], r["seed"]): r for r in after["coverage_records"]}
    pairs: dict[str, list[tuple[dict, dict]]] = {}
    for record in before["coverage_records"]:
        match = later.get((record["arm"], record["seed"]))
        if match is not None:
            pairs.setdefault(record["arm"], []).append((record, match))
    return pairs


def compare_parameter(pairs: Sequence[tuple[Mapping, Mapping]], name: str) -> dict[str, Any]:
    """Same-data check, posterior shift and spread ratio, and verdict changes of one parameter."""
    early = [b["params"][name] for b, _ in pairs]
    late = [a["params"][name] for _, a in pairs]
    ls_shift = np.array([(q["ls_value"] - p["ls_value"]) / p["ls_stderr"] for p, q in zip(early, late)])
    shift = np.array([(q["median"] - p["median"]) / p["sd"] for p, q in zip(early, late)])
    ratio = np.array([q["sd"] / p["sd"] for p, q in zip(early, late)])
    # Monte Carlo error of the difference of two medians (module docstring)
    inverse_ess = np.array([1 / b["ess_min"] + 1 / a["ess_min"] for b, a in pairs])
    expected = math.sqrt(math.pi / 2 * np.mean(inverse_ess))
    return {
        "least_squares_shift_over_stderr_max_abs": float(np.max(np.abs(ls_shift))),
        "median_shift_over_sd": {"mean": float(np.mean(shift)), "rms": float(np.sqrt(np.mean(shift ** 2))),
                                 "max_abs": float(np.max(np.abs(shift))),
                                 "rms_expected_from_ess": float(expected)},
        "sd_ratio": {"median": float(np.median(ratio)), "p5": float(np.percentile(ratio, 5)),
                     "p95": float(np.percentile(ratio, 95)), "log_rms": float(np.sqrt(np.mean(np.log(ratio) ** 2))),
                     "log_rms_expected_from_ess": math.sqrt(0.5 * np.mean(inverse_ess))},
        "verdict_changes": {level: int(sum(p[f"in{level}"] != q[f"in{level}"] for p, q in zip(early, late)))
                            for level in ("68", "95")},
        "coverage": {level: [int(sum(p[f"in{level}"] for p in early)), int(sum(q[f"in{level}"] for q in late))]
                     for level in ("68", "95")},
    }


def uniformity(records: Sequence[Mapping], name: str, draws: int, bins: int) -> dict[str, Any]:
    """The SBC rank test of calibration.py (ranks 0..``draws`` in ``bins`` bins) and the
    same test on the Gaussian PIT Phi(-z)."""
    ranks = np.array([r["params"][name]["rank"] for r in records])
    pit = stats.norm.cdf(-np.array([r["params"][name]["z"] for r in records]))
    counts = np.histogram(pit, bins=bins, range=(0.0, 1.0))[0]
    rank_counts = np.histogram(ranks, bins=np.linspace(0, draws + 1, bins + 1))[0]
    return {"rank_counts": rank_counts.tolist(), "rank_chi2_p": float(stats.chisquare(rank_counts).pvalue),
            "pit_counts": counts.tolist(), "pit_chi2_p": float(stats.chisquare(counts).pvalue),
            "pit_ks_p": float(stats.kstest(pit, "uniform").pvalue),
            "rank_pit_correlation": float(np.corrcoef(ranks, pit)[0, 1])}


def compare_arm(pairs: Sequence[tuple[Mapping, Mapping]], draws: int, bins: int) -> dict[str, Any]:
    """Every parameter of one arm, with the chains' lengths and sizes in both runs
    (``draws`` and ``bins``: the SBC design of calibration.py)."""
    def median(key: str, which: int) -> float:
        return float(np.median([pair[which][key] for pair in pairs]))

    return {"n": len(pairs),
            "steps_median": [median("n_steps", 0), median("n_steps", 1)],
            "samples_median": [median("n_samples", 0), median("n_samples", 1)],
            "tau_max_median": [median("tau_max", 0), median("tau_max", 1)],
            "params": {name: compare_parameter(pairs, name) for name in PARAMETERS},
            "uniformity": {name: [uniformity([pair[which] for pair in pairs], name, draws, bins) for which in (0, 1)]
                           for name in PARAMETERS}}


def print_summary(payload: Mapping[str, Any]) -> None:
    print(f"before: {payload['before']['commit']} ({payload['before']['mcmc']})")
    print(f"after:  {payload['after']['commit']} ({payload['after']['mcmc']})")
    for arm, result in payload["arms"].items():
        steps, samples = result["steps_median"], result["samples_median"]
        print(f"\n== {arm}: {result['n']} paired seeds; median steps {steps[0]:.0f} -> {steps[1]:.0f}, "
              f"kept samples {samples[0]:.0f} -> {samples[1]:.0f}")
        for name, p in result["params"].items():
            s, r = p["median_shift_over_sd"], p["sd_ratio"]
            print(f"{name:<6} same data: least squares moved at most {p['least_squares_shift_over_stderr_max_abs']:.2g} "
                  f"stderr; median shift / sd mean {s['mean']:+.3f} rms {s['rms']:.3f} (Monte Carlo "
                  f"{s['rms_expected_from_ess']:.3f}) max {s['max_abs']:.3f}; "
                  f"sd ratio {r['median']:.4f} [{r['p5']:.3f}, {r['p95']:.3f}], log rms {r['log_rms']:.4f} (Monte "
                  f"Carlo {r['log_rms_expected_from_ess']:.4f}); verdicts changed "
                  f"{p['verdict_changes']['68']} (68 %), {p['verdict_changes']['95']} (95 %); coverage 68 % "
                  f"{p['coverage']['68'][0]} -> {p['coverage']['68'][1]}, 95 % {p['coverage']['95'][0]} -> "
                  f"{p['coverage']['95'][1]}")
            for run, u in zip(("before", "after"), result["uniformity"][name]):
                print(f"{'':<6}{run:<7} SBC ranks {u['rank_counts']} chi-square p {u['rank_chi2_p']:.3g}; "
                      f"Phi(-z) {u['pit_counts']} chi-square p {u['pit_chi2_p']:.3g}, KS p {u['pit_ks_p']:.3g}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="the earlier calibration.json: a path or a git revision")
    parser.add_argument("--after", default=CALIBRATION_JSON, help="the later one (default: %(default)s)")
    args = parser.parse_args(argv)
    before, after = load_calibration(args.before), load_calibration(args.after)
    differences = design_differences(before, after)
    if differences:
        raise SystemExit(f"the two runs are different studies (their designs differ in {', '.join(differences)}); "
                         "only the MCMC may differ between runs compared seed by seed")
    pairs = paired_records(before, after)
    if not pairs:
        raise SystemExit("the two runs have no coverage seed in common")
    payload = {
        "benchmark": "calibration_paired",
        "command": f"python benchmarks/calibration_paired.py --before {args.before}",
        "before": {"source": args.before, "commit": before["git"]["commit"], "mcmc": before["design"]["mcmc"]},
        "after": {"source": args.after, "commit": after["git"]["commit"], "mcmc": after["design"]["mcmc"]},
        "arms": {arm: compare_arm(arm_pairs, after["design"]["sbc_draws"], after["design"]["rank_bins"])
                 for arm, arm_pairs in pairs.items()},
    }
    path = write_json("calibration_paired", payload)
    print_summary(payload)
    print(f"\nwrote {path.relative_to(ROOT)} (in {OUT.relative_to(ROOT)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``gonio demo``: the whole path on the embedded emulator, end to end.

1. Start the emulated rig in-process with the paper's wall plaster as the sample
   (``oren-nayar``, sigma = 30 deg, rho = 0.9: Oren & Nayar 1995, Fig 16).
2. Run the Fig 16 (plane of incidence) and Fig 19 (off-plane) protocols, with a diffuse
   reflectance standard for absolute calibration; every point is recorded as measured.
3. Reduce the recordings, compare models by least squares (lambert,
   oren-nayar-qualitative, oren-nayar) and fit ``oren-nayar`` with MCMC (the model
   averaged over the rig's apertures, the calibration as a prior, an extra-noise term).
4. Write the fitting report and print where it is, with the fitted parameters against
   the truth.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import time
import warnings
from pathlib import Path

from . import CLIError
from .progress import ProgressLine

#: The emulated sample and its true parameters.
SAMPLE_MODEL = "oren-nayar"
TRUTH = {"rho": 0.9, "sigma": 30.0}
#: The shipped protocols the demo runs.
PROTOCOLS = ("oren-nayar-fig16-plaster.toml", "oren-nayar-fig19-off-plane.toml")
#: Marks a folder as the demo's own output, which a new demo run may replace.
MARKER = ".gonio-demo"


def protocols_folder() -> Path:
    """The shipped protocols/ folder of the source tree gonio runs from."""
    folder = Path(__file__).resolve().parents[2] / "protocols"
    if not folder.is_dir():
        raise CLIError(f"shipped protocols not found at {folder}: run the demo from a gonio source checkout")
    return folder


def _prepare_output(out: Path) -> None:
    if out.exists() and any(out.iterdir()):
        if not (out / MARKER).exists():
            raise CLIError(f"{out} exists and is not a gonio demo folder; choose another --out "
                           "(gonio never overwrites data it did not write)")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("output of 'gonio demo'; a new demo run replaces this folder\n")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio demo``."""
    parser = subparsers.add_parser(
        "demo",
        help="measure the paper's wall plaster on the emulated rig, fit it with MCMC, write the report",
        description=__doc__.split("\n\n")[0] + " Takes about a minute on two cores.",
    )
    parser.add_argument("--out", default="gonio-demo", help="output folder (default gonio-demo)")
    parser.add_argument("--seed", type=int, default=0, help="emulator and sampler seed (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(func=_run)


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, flush=True)


def measure_demo(out: Path, seed: int = 0, quiet: bool = True):
    """Measure the demo protocols on the emulated plaster into ``out/recordings``.

    Returns
    -------
    gonio.acquisition.Reduced
        The recordings reduced and combined.
    """
    from gonio import acquisition, protocols

    from .run import emulated_rig

    sample = f"{SAMPLE_MODEL}:" + ",".join(f"{k}={v:g}" for k, v in TRUTH.items())
    folders = []
    _say(quiet, f"gonio demo: emulated rig with sample {sample} (seed {seed})")
    with emulated_rig(sample, seed, name=f"gonio-demo-{seed}") as (rig, emulator, change_sample, metadata):
        for name in PROTOCOLS:
            protocol = protocols.load(protocols_folder() / name)
            folder = out / "recordings" / protocol.name
            _say(quiet, f"measuring {protocol.name}: {protocol.description}")
            line = None if quiet else ProgressLine("points")
            reflectance = protocol.reference.reflectance if protocol.reference else None
            result = acquisition.run_protocol(
                protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                change_sample=lambda which, r=reflectance: change_sample(which, r),
                progress=None if line is None else (lambda p, line=line: line.update(p.done, p.total, p.eta_wall)),
            )
            _say(quiet, "  " + result.summary())
            folders.append(folder)
    return acquisition.combine_reduced([acquisition.reduce_recording(f) for f in folders],
                                       label="wall plaster (emulated)")


def fit_demo(reduced, seed: int = 0, quiet: bool = True):
    """Compare models and fit ``oren-nayar`` with MCMC as the demo does.

    The dataset is relative radiance with the reference-standard prior on its scale, the
    model is averaged over the rig's apertures, ``ir_weight`` is fixed at 1 (the paper's
    model) and an extra-noise term absorbs lamp flicker the CCD noise model does not know.

    Returns
    -------
    result : gonio.fitting.FitResult
    comparison : gonio.fitting.ModelComparison
    """
    from gonio.fitting import ConvergenceWarning, compare_models, fit

    dataset, priors = reduced.fit_inputs()
    _say(quiet, f"fitting {dataset.n} {dataset.quantity} values "
                f"(model averaged over the rig's apertures {dataset.metadata.get('aperture_sr')} sr)")
    comparison = compare_models(dataset, ["lambert", "oren-nayar-qualitative", (SAMPLE_MODEL, {"ir_weight": 1.0})])
    _say(quiet, comparison.summary())
    line = None if quiet else ProgressLine("MCMC steps")

    def progress(step: int, max_steps: int, tau: float) -> None:
        if line is not None:
            line.update(step, max_steps, None, f"max tau {tau:.1f}")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # reported in the result, loudly
        result = fit(dataset, SAMPLE_MODEL, fixed={"ir_weight": 1.0}, priors=priors, jitter=True,
                     seed=seed, progress=progress)
    return result, comparison


def _run(args: argparse.Namespace) -> int:
    from gonio.report.fit_report import write_report

    start = time.perf_counter()
    out = Path(args.out)
    _prepare_output(out)
    reduced = measure_demo(out, args.seed, args.quiet)
    result, comparison = fit_demo(reduced, args.seed, args.quiet)
    fit_folder = out / f"fit-{SAMPLE_MODEL}"
    result.save(fit_folder)
    (fit_folder / "model-comparison.txt").write_text(comparison.summary() + "\n")
    report = write_report(fit_folder)
    print()
    print(result.summary())
    print()
    print(truth_table(result))
    print()
    print(f"recordings: {(out / 'recordings').resolve()}")
    print(f"report:     {report.resolve()}")
    print(f"gonio demo finished in {time.perf_counter() - start:.0f} s")
    if result.converged is False:
        print("gonio: WARNING: the MCMC chain did NOT converge; see the report", file=sys.stderr)
        return 1
    return 0


def truth_table(result) -> str:
    """Fitted parameters against the emulator's truth, with the 95 % interval."""
    rows = {row["name"]: row for row in result.parameter_rows()}
    lines = ["parameter   truth     fitted (median)   95 % interval           truth inside"]
    for name, truth in TRUTH.items():
        row = rows[name]
        low, high = row.get("p2_5"), row.get("p97_5")
        inside = "yes" if low is not None and low <= truth <= high else "NO"
        lines.append(f"{name:<10} {truth:8.4g}   {row.get('median', row['value']):12.5g}      "
                     f"[{low:.5g}, {high:.5g}] {row['unit']:<6}  {inside}")
    return "\n".join(lines)

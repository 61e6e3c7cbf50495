"""``gonio demo``: the whole path on the embedded emulator, end to end.

1. Start the emulated rig in-process with the paper's wall plaster as the sample: the
   physical V-cavity model ``oren-nayar-exact`` (Oren & Nayar 1995, eq 8, 15, 22-24, 32),
   sigma = 30 deg, rho = 0.9 (Fig 16), not a formula the fit could be handed.
2. Run the Fig 16 (plane of incidence) and Fig 19 (off-plane) protocols, with a diffuse
   reflectance standard for absolute calibration; every point is recorded as measured.
3. Reduce the recordings (every value with its uncertainty budget: CCD, lamp monitor and
   what it does not see, the sample's texture, angle; the calibration from the reference
   standard) and compare the candidate models of :data:`CANDIDATES` under the fit's own
   likelihood (the model averaged over the rig's apertures, the calibration as a prior, no
   extra-noise term: the stated uncertainties are the whole noise). On a rig with
   systematic errors (the default realism, ``lab``) every candidate gets the rig's errors
   as parameters (:data:`RIG_ERRORS`: the axes' zero offsets and the sample's tilt, stray
   light) and the calibration per incidence (docs/fitting.md, "The rig's errors as
   parameters"). The comparison chooses the simplest model that passes the
   goodness-of-fit test (:mod:`gonio.fitting.selection`).
4. Fit the chosen model with MCMC, write the fitting report, and print the fitted
   parameters against the truth; a truth outside its 95 % interval is flagged with the
   bias in units of the interval.

The exit status is that of the fit (docs/fitting.md, "Exit codes"): 0 converged and
adequate, 3 not converged, 4 model inadequate, 5 noise understated, 2 bad input.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

from gonio.sample_specs import DEFAULT_SAMPLE, PLASTER_MODEL, PLASTER_TRUTH

from . import CLIError
from .progress import ProgressLine
from .realism import DEFAULT_REALISM, IDEAL_RIG_NOTE, REALISM_HELP, REALISM_SYNTAX

#: The emulated sample and its true parameters (``--sample``'s default, gonio.sample_specs).
SAMPLE_MODEL, TRUTH = PLASTER_MODEL, PLASTER_TRUTH
#: Parameters of a sample spec that the candidates can recover (the truth table's rows).
TRUTH_PARAMETERS = ("rho", "sigma")
#: The models the demo compares: Lambert, the qualitative model (eq 30), the paper's
#: approximation (eq 33-35, its interreflection term at full weight) and the table of the
#: exact model (docs/tabulated.md).
CANDIDATES = ("lambert", "oren-nayar-qualitative", ("oren-nayar", {"ir_weight": 1.0}), "oren-nayar-tabulated")
#: What the demo's fits model of a rig with systematic errors: every alignment parameter and
#: the stray light, with the calibration per incidence (the remedies of docs/fitting.md).
RIG_ERRORS = {"alignment": "all", "stray_light": True}
#: The folder (in the output folder) of the chosen model's fit.
FIT_FOLDER = "fit"
#: The fit folder of older demos (the layout an old text marker stands for).
LEGACY_FIT_FOLDER = "fit-oren-nayar"
#: The shipped protocols the demo runs.
PROTOCOLS = ("oren-nayar-fig16-plaster.toml", "oren-nayar-fig19-off-plane.toml")
#: Marks a folder as the demo's own output and lists what the demo wrote there, which a
#: new demo run deletes (nothing else).
MARKER = ".gonio-demo"
#: The truth table the demo writes next to the fit result (the comparison is saved with
#: the result: comparison.json, comparison.txt).
TRUTH_FILE = "truth.txt"
#: Where older demos wrote the comparison (a new run deletes them with the rest).
LEGACY_COMPARISON_FILES = ("model-comparison.txt", "model-comparison.json")


def protocols_folder() -> Path:
    """The shipped protocols/ folder of the source tree gonio runs from."""
    folder = Path(__file__).resolve().parents[2] / "protocols"
    if not folder.is_dir():
        raise CLIError(f"shipped protocols not found at {folder}: run the demo from a gonio source checkout")
    return folder


def demo_paths(fit_folder: str = FIT_FOLDER) -> tuple[list[str], list[str]]:
    """The files and folders the demo writes in its output folder, relative to it.

    Returns
    -------
    files : list of str
        The recording files of every protocol (gonio.data.RECORDING_FILES), the fit
        result and report files, the model comparison and the truth table.
    folders : list of str
        The folders holding them (a new run removes them only when they are empty).
    """
    from gonio import protocols
    from gonio.data import RECORDING_FILES

    from .fit import result_file_names

    recordings = [f"recordings/{protocols.load(protocols_folder() / name).name}" for name in PROTOCOLS]
    files = [f"{folder}/{name}" for folder in recordings for name in RECORDING_FILES]
    files += [f"{fit_folder}/{name}" for name in result_file_names() + (TRUTH_FILE,) + LEGACY_COMPARISON_FILES]
    return files, recordings + ["recordings", fit_folder]


def _recorded_paths(out: Path) -> tuple[list[str], list[str]]:
    """The files and folders an earlier demo run recorded in its marker.

    A marker of an older gonio (plain text, no list) stands for the demo's fixed layout
    (:func:`demo_paths`, with the older fit folder), which is what that demo wrote.
    """
    try:
        recorded = json.loads((out / MARKER).read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError):
        return demo_paths(LEGACY_FIT_FOLDER)
    if not isinstance(recorded, dict):
        return demo_paths(LEGACY_FIT_FOLDER)
    files, folders = recorded.get("files", []), recorded.get("folders", [])
    valid = all(isinstance(v, list) and all(isinstance(p, str) for p in v) for v in (files, folders))
    return (files, folders) if valid else demo_paths(LEGACY_FIT_FOLDER)


def _inside(out: Path, relative: str) -> Path | None:
    """``out / relative`` if it stays inside ``out`` with no symbolic link on the way, else None."""
    parts = Path(relative).parts
    if not parts or Path(relative).is_absolute() or any(part in ("", ".", "..") for part in parts):
        return None
    path = out
    for part in parts[:-1]:
        path = path / part
        if path.is_symlink() or not path.is_dir():
            return None
    return path / parts[-1]


def _remove_earlier_output(out: Path) -> None:
    """Delete what an earlier demo run recorded in its marker, and nothing else.

    Recorded files are deleted; recorded folders only when they are empty afterwards, so
    every file a user put into the output folder stays where it is.
    """
    files, folders = _recorded_paths(out)
    for relative in files:
        path = _inside(out, relative)
        if path is not None and (path.is_symlink() or path.is_file()):
            path.unlink()
    for relative in sorted(folders, key=lambda p: len(Path(p).parts), reverse=True):
        path = _inside(out, relative)
        if path is not None and not path.is_symlink() and path.is_dir() and not any(path.iterdir()):
            path.rmdir()


def _prepare_output(out: str | Path) -> Path:
    """Check ``--out`` and clear what an earlier demo run wrote there.

    Parameters
    ----------
    out : str or Path
        The ``--out`` argument.

    Returns
    -------
    pathlib.Path
        The output folder, created, holding a fresh marker that lists the paths this run
        writes.

    Raises
    ------
    CLIError
        For an empty name, a symbolic link, an existing file, or a folder holding files
        but no demo marker (gonio never overwrites data it did not write).
    """
    if not str(out).strip():
        raise CLIError(f"--out {str(out)!r}: expected the name of an output folder")
    out = Path(out)
    if out.is_symlink():
        raise CLIError(f"--out {out}: is a symbolic link; give the folder itself (the demo never writes or "
                       "deletes through a link)")
    if out.exists() and not out.is_dir():
        kind = "an existing file" if out.is_file() else "a device or special file"
        raise CLIError(f"--out {out}: is {kind}; expected an output folder")
    if out.exists() and any(out.iterdir()):
        marker = out / MARKER
        if marker.is_symlink() or not marker.is_file():
            raise CLIError(f"--out {out}: exists and is not a gonio demo folder; choose another --out "
                           "(gonio never overwrites data it did not write)")
        _remove_earlier_output(out)
    files, folders = demo_paths()
    out.mkdir(parents=True, exist_ok=True)
    record = {"written_by": "gonio demo", "note": "a new demo run deletes these files (and these folders when "
              "empty), nothing else", "files": files, "folders": folders}
    (out / MARKER).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio demo``."""
    parser = subparsers.add_parser(
        "demo",
        help="measure the paper's wall plaster on the emulated rig, choose and fit a model with MCMC, write the report",
        description=__doc__.split("\n\n")[0] + " Takes 20-25 s on two cores. Exit status: 0 converged and "
                    "adequate, 3 chain not converged, 4 model inadequate, 5 noise understated, 2 bad input "
                    "(docs/fitting.md).",
    )
    parser.add_argument("--out", default="gonio-demo", help="output folder (default gonio-demo)")
    parser.add_argument("--sample", default=DEFAULT_SAMPLE, metavar="MODEL[:k=v,...]|surface:kind=...|curet:NUMBER|NAME",
                        help=f"the emulated sample (default {DEFAULT_SAMPLE}, the paper's wall plaster); e.g. "
                             "surface:kind=vgrooves,sigma=30,rho=0.9, a rendered V-groove field (docs/surfaces.md)")
    parser.add_argument("--seed", type=int, default=0, help="emulator and sampler seed (default 0)")
    parser.add_argument("--realism", default=DEFAULT_REALISM, metavar=REALISM_SYNTAX,
                        help=REALISM_HELP + "; with any systematic error the demo's fits take the rig's errors as "
                             "parameters and calibrate per incidence")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(func=_run)


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, flush=True)


def sample_truth(sample: str) -> dict[str, float]:
    """The true values of :data:`TRUTH_PARAMETERS` that a sample spec states.

    A model's parameters, or a rendered surface's (the height field's sigma is the
    Oren-Nayar roughness it is matched to, docs/surfaces.md); none for a CUReT material.

    Examples
    --------
    >>> sample_truth("surface:kind=vgrooves,sigma=20,rho=0.5")
    {'rho': 0.5, 'sigma': 20.0}
    """
    from .samples import parse_sample_spec

    parameters = parse_sample_spec(sample).parameters
    return {name: float(parameters[name]) for name in TRUTH_PARAMETERS
            if isinstance(parameters.get(name), (int, float)) and not isinstance(parameters.get(name), bool)}


def measure_demo(out: Path, seed: int = 0, quiet: bool = True, sample: str = DEFAULT_SAMPLE,
                 realism: str = DEFAULT_REALISM):
    """Measure the demo protocols on the emulated sample into ``out/recordings``.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    seed : int
        Emulator seed.
    quiet : bool
        No progress lines.
    sample : str
        The sample spec (default: the paper's wall plaster, :data:`DEFAULT_SAMPLE`).
    realism : str
        The rig's departures from the ideal (:func:`gonio.cli.realism.parse_realism`;
        default a real lab's rig).

    Returns
    -------
    gonio.acquisition.Reduced
        The recordings reduced and combined.
    """
    from gonio import acquisition, protocols

    from .run import emulated_rig

    folders = []
    _say(quiet, f"gonio demo: emulated rig with sample {sample} (seed {seed}, realism {realism})")
    with emulated_rig(sample, seed, name=f"gonio-demo-{seed}", realism=realism) as (rig, emulator, change_sample,
                                                                                   metadata):
        if emulator.systematics.is_ideal:
            _say(quiet, IDEAL_RIG_NOTE)
        for name in PROTOCOLS:
            protocol = protocols.load(protocols_folder() / name)
            folder = out / "recordings" / protocol.name
            _say(quiet, f"measuring {protocol.name}: {protocol.description}")
            line = None if quiet else ProgressLine("points")
            reflectance = protocol.reference.reflectance if protocol.reference else None
            result = acquisition.run_protocol(
                protocol, rig, folder, metadata=metadata, clock=emulator.control.now,
                change_sample=lambda which, r=reflectance, **how: change_sample(which, r, **how),
                progress=None if line is None else (lambda p, line=line: line.update(p.done, p.total, p.eta_wall)),
            )
            _say(quiet, "  " + result.summary())
            folders.append(folder)
    label = "wall plaster (emulated)" if sample == DEFAULT_SAMPLE else f"{sample} (emulated)"
    return acquisition.combine_reduced([acquisition.reduce_recording(f) for f in folders], label=label)


def rig_errors_modelled(realism: str) -> bool:
    """Whether the demo's fits take the rig's errors as parameters: on any rig with a
    systematic error (misalignment, stray light, non-linearity, beam profile, wedge), not on
    the ideal one."""
    from .realism import parse_realism

    systematics = parse_realism(realism, 0)
    return not systematics.only("view_offset", "theta_i_offset", "phi_i_offset", "tilt_x", "tilt_y", "stray_light",
                                "nonlinearity", "beam_falloff", "wedge", "mount_tilt").is_ideal


def fit_demo(reduced, seed: int = 0, quiet: bool = True, realism: str = DEFAULT_REALISM):
    """Compare the :data:`CANDIDATES` and fit the chosen model with MCMC, as the demo does.

    The dataset is relative radiance with the reference-standard prior on its scale, the
    models are averaged over the rig's apertures. No extra-noise term unless the verdict asks
    for one (``jitter="auto"``, :mod:`gonio.fitting.adequacy`): the lamp monitor removes the
    lamp's flicker and drift and the reduction's budget states every remaining noise, so
    the least-squares reduced chi-square of an adequate model is near 1
    (docs/acquisition.md); the comparison and the fit share this likelihood. On a rig with
    systematic errors (:func:`rig_errors_modelled`) the dataset is calibrated per
    incidence and every fit has the rig's errors as parameters (:data:`RIG_ERRORS`).

    Returns
    -------
    result : gonio.fitting.FitResult
    comparison : gonio.fitting.ModelComparison
    """
    from gonio.fitting import ConvergenceWarning, compare_models, fit
    from gonio.fitting.rig_errors import ALIGNMENT_NAMES

    modelled = rig_errors_modelled(realism)
    errors = RIG_ERRORS if modelled else {}
    dataset, priors = reduced.fit_inputs("per-incidence" if modelled else "common")
    _say(quiet, f"comparing models on {dataset.n} {dataset.quantity} values "
                f"(averaged over the rig's apertures {dataset.metadata.get('aperture_sr')} sr"
                + (f"; the rig's errors as parameters: alignment ({len(ALIGNMENT_NAMES)}), stray light; calibrated per incidence)"
                   if modelled else ")"))
    comparison = compare_models(dataset, CANDIDATES, priors=priors, jitter="auto", **errors)
    _say(quiet, comparison.summary())
    chosen = comparison.row(comparison.chosen)
    _say(quiet, f"fitting {comparison.chosen} with MCMC")
    line = None if quiet else ProgressLine("MCMC steps of those convergence needs (50 tau)")

    needed = [0]

    def progress(step: int, max_steps: int, tau: float) -> None:
        if line is not None:  # toward convergence, not toward the step limit; full only when it is reached
            needed[0] = int(min(max_steps, 50 * tau)) if math.isfinite(tau) and tau > 0 else max_steps
            settling = "; length reached, tau and R-hat settling" if step >= needed[0] else ""
            line.update(min(step, needed[0] - 1), needed[0], None, f"tau {tau:.3g}; limit {max_steps}{settling}")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # reported in the result, loudly
        result = fit(dataset, chosen["model"], fixed=chosen["fixed"], priors=priors, seed=seed, progress=progress,
                     jitter=comparison.jitter or "auto", least_squares=comparison.fits[comparison.chosen], **errors)
    if line is not None and result.mcmc is not None:
        line.update(result.mcmc.n_steps, result.mcmc.n_steps, None, "converged" if result.converged else
                    "step limit reached: NOT converged")
    return result, comparison


def _run(args: argparse.Namespace) -> int:
    from gonio.report.fit_report import write_report

    from .samples import parse_sample_spec

    start = time.perf_counter()
    parse_sample_spec(args.sample)  # a bad spec fails before anything is written
    truth = sample_truth(args.sample)
    out = _prepare_output(args.out)
    reduced = measure_demo(out, args.seed, args.quiet, args.sample, args.realism)
    result, comparison = fit_demo(reduced, args.seed, args.quiet, args.realism)
    fit_folder = out / FIT_FOLDER
    result.comparison = comparison.to_dict()
    result.save(fit_folder)
    table = truth_table(result, truth, args.sample, args.realism)
    described = SAMPLE_MODEL if args.sample == DEFAULT_SAMPLE else args.sample
    (fit_folder / TRUTH_FILE).write_text(f"sample: {described}\n{table}\n")
    report = write_report(fit_folder)
    print()
    print(result.summary())
    print()
    print(f"sample {described}; chosen and fitted {comparison.chosen}")
    print(table)
    noise = "no extra-noise term" if result.jitter is None else f"with the extra-noise term {result.jitter}"
    print(f"least-squares reduced chi-square {result.least_squares.redchi:.3f} ({result.dataset.n} values, {noise})")
    print()
    print(f"recordings: {(out / 'recordings').resolve()}")
    print(f"report:     {report.resolve()}")
    print(f"gonio demo finished in {time.perf_counter() - start:.0f} s")
    if result.converged is False:
        print("gonio: WARNING: the MCMC chain did NOT converge; see the report", file=sys.stderr)
    if result.adequate is False:
        print(f"gonio: {result.adequacy.headline()}", file=sys.stderr)
    return result.exit_code()


def truth_table(result, truth: dict[str, float] | None = None, sample: str = DEFAULT_SAMPLE,
                realism: str = DEFAULT_REALISM) -> str:
    """Fitted parameters against the emulator's truth, with the 95 % interval.

    ``truth`` defaults to :data:`TRUTH` (the default sample's).  A truth outside its
    interval is flagged with the bias (median - truth) in units of the interval's
    half-width on that side, blamed on the fitted model: on the ideal rig the model alone,
    on a rig with systematic errors the model with the rig's errors as parameters (the
    demo's fits, :func:`rig_errors_modelled`); a parameter the fitted model does not have
    is named as such.
    """
    truth = TRUTH if truth is None else truth
    described = SAMPLE_MODEL if sample == DEFAULT_SAMPLE else sample
    cause = (f"{result.model} does not reproduce the sample's {described} within these data's noise"
             if not rig_errors_modelled(realism) else
             f"{result.model} with the rig's errors as parameters (--realism {realism}) does not reproduce the "
             f"sample's {described} within these data's noise")
    from gonio.fitting.truth import truth_lines

    lines, flags = truth_lines(result.parameter_rows(), truth, result.model, cause)
    if not truth:
        lines.append(f"(the sample {sample} states no value of {', '.join(TRUTH_PARAMETERS)})")
    return "\n".join(lines + flags)

"""``gonio run``: measure a sweep protocol on the emulated or a real rig."""
from __future__ import annotations

import argparse
import functools
import math
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

import gonio

from . import CLIError
from .realism import DEFAULT_REALISM, IDEAL_RIG_NOTE, REALISM_HELP, REALISM_SYNTAX, parse_realism, realism_metadata
from gonio.sample_specs import DEFAULT_SAMPLE

from .samples import SPEC_SYNTAX, parse_sample_spec
from .paths import check_output_folder
from .progress import ProgressLine
from .arguments import name_value_pairs, number, parse_duration, prior_ranges

#: Default instrument time of one batch of an adaptive run [s] (gonio.adaptive.DEFAULT_BATCH_SECONDS).
DEFAULT_BATCH = 60
#: The adaptive options, as ``(attribute, option)``: refused without --adaptive.
_ADAPTIVE_OPTIONS = (("model", "--model"), ("until", "--until"), ("budget", "--budget"), ("batch", "--batch"),
                     ("prior", "--prior"), ("fix", "--fix"), ("calibration", "--calibration"),
                     ("alignment", "--alignment"), ("stray_light", "--stray-light"), ("max_angle", "--max-angle"))

if TYPE_CHECKING:  # loaded by the command itself: every gonio command builds this parser
    from gonio import acquisition, adaptive, protocols

def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio run``."""
    parser = subparsers.add_parser(
        "run",
        help="measure a sweep protocol on the emulated rig (default) or a real one",
        description=(
            "Run a protocol on the rig and record every point as it is measured (see "
            "docs/data-format.md). Without --stage/--camera/--lamp an emulated rig is started "
            "in-process with --sample as the sample (else the protocol's [sample] emulated, else "
            f"{DEFAULT_SAMPLE}). Ctrl-C stops cleanly; --resume continues."
        ),
    )
    parser.add_argument("protocol", help="protocol TOML file (docs/protocols.md)")
    parser.add_argument("--out", required=True, help="recording folder (created; never overwritten)")
    parser.add_argument("--resume", action="store_true", help="continue an interrupted recording in --out")
    parser.add_argument("--sample", default=None, metavar="MODEL[:k=v,...]|surface:kind=...|curet:NUMBER|NAME",
                        help="emulated sample: a model, a rendered surface (e.g. surface:kind=vgrooves,sigma=30,rho=0.9) "
                             "or a CUReT material (e.g. curet:plaster_a); default: the protocol's [sample] emulated, "
                             f"else {DEFAULT_SAMPLE}")
    parser.add_argument("--seed", type=int, default=0, help="emulator seed (default 0)")
    parser.add_argument("--realism", default=DEFAULT_REALISM, metavar=REALISM_SYNTAX, help=REALISM_HELP)
    parser.add_argument("--stage", help="stage port or URL of a real rig (e.g. /dev/ttyUSB0)")
    parser.add_argument("--camera", help="camera port or URL of a real rig")
    parser.add_argument("--lamp", help="lamp supply port or URL of a real rig")
    parser.add_argument("--lamp-voltage", type=float, default=120.0, help="lamp voltage [V] (default 120)")
    parser.add_argument("--no-monitor", action="store_true",
                        help="emulated rig without a lamp monitor (use [checks] in the protocol; docs/acquisition.md)")
    parser.add_argument("--no-warm-up", action="store_true", help="do not wait for the lamp to stabilise")
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    _register_adaptive(parser)
    parser.set_defaults(func=_run)


def _register_adaptive(parser: argparse.ArgumentParser) -> None:
    """The options of an adaptive run (docs/design.md, "Adaptive runs")."""
    group = parser.add_argument_group(
        "adaptive runs", "after the protocol's points, fit and choose the next batch from the posterior until the "
                         "target widths or the budget (docs/design.md)")
    group.add_argument("--adaptive", action="store_true", help="run adaptively (needs --model, --until, --budget)")
    group.add_argument("--model", help="registered model fitted after each batch (see 'gonio models')")
    group.add_argument("--until", action="append", default=[], metavar="NAME=WIDTH",
                       help="stop when the 95 %% interval of NAME is at most WIDTH wide (repeatable; all must hold)")
    group.add_argument("--budget", metavar="SECONDS|Nmin|Nh",
                       help="the most instrument time the whole run may take, as gonio plan estimates it")
    group.add_argument("--batch", default=None, metavar="SECONDS|Nmin",
                       help=f"instrument time of one batch, at most (default {DEFAULT_BATCH}s)")
    group.add_argument("--prior", action="append", default=[], metavar="NAME=LOW:HIGH",
                       help="uniform prior range of a parameter (default: its physical bounds); every parameter not "
                            "--fix'ed is fitted")
    group.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help="hold a parameter fixed")
    group.add_argument("--calibration", choices=["per-incidence", "common"], default=None,
                       help="the fit's calibration (default per-incidence: new points only at the lamp angles the "
                            "reference standard is read at)")
    group.add_argument("--alignment", default=None, metavar="all|none|NAMES",
                       help="the rig's alignment errors the fit frees (default all)")
    group.add_argument("--stray-light", action=argparse.BooleanOptionalAction, default=None,
                       help="fit the rig's stray light (default yes)")
    group.add_argument("--max-angle", type=float, default=None, metavar="DEG",
                       help="largest lamp and camera angle from the normal for new points (default 90)")


@contextmanager
def emulated_rig(sample: str, seed: int, name: str = "gonio-run", realism: str = DEFAULT_REALISM,
                 remount_time: float = 60.0, **emulator_options) -> Iterator[tuple]:
    """An in-process emulated rig with a sample spec as sample, opened through the drivers.

    Yields ``(rig, emulator, change_sample, metadata)``: the driver-level Rig, the emulator
    (for its clock), a function ``change_sample(which, reflectance=None, mounting=None)``
    swapping the sample for a Lambertian reference standard of that reflectance and back,
    or (``mounting``, a :class:`gonio.acquisition.SampleMounting`) remounting the sample,
    each taking the operator ``remount_time`` seconds, and the configuration to store with
    the recording. ``realism`` is the rig's
    systematic errors as a spec (:func:`parse_realism`); the spec and every magnitude it
    gave are stored in ``metadata["rig"]["realism"]``, so a resume with another realism is
    refused naming the field. ``emulator_options`` go to
    :class:`drivers.emulator.rig.EmulatedRig` (e.g. ``monitor=False``,
    ``lamp_params=...``); plain values among them are stored in the metadata.
    """
    from drivers.emulator.rig import EmulatedRig
    from drivers.rig import Rig

    parsed = parse_sample_spec(sample)
    parsed.prepare()  # a rendered surface's table: loaded, or rendered now with progress
    brdf = parsed.brdf
    systematics = parse_realism(realism, seed)
    emulator = EmulatedRig(brdf, seed=seed, name=name, systematics=systematics,
                           **{"lamp_warm": False, **emulator_options})
    emulator.start(pty=False)
    try:
        rig = Rig.open(emulator.url("stage"), emulator.url("camera"), emulator.url("lamp"))
        try:
            def change_sample(which: str, reflectance: float | None = None, mounting=None) -> None:
                if which == "sample":
                    index, rotation, spin = (0, 0.0, False) if mounting is None else (
                        mounting.index, mounting.rotation, mounting.spin)
                    emulator.control.remount(index, rotation, spin, handling_s=remount_time)
                else:
                    emulator.control.mount_sample(functools.partial(gonio.brdf, "lambert", rho=reflectance),
                                                  handling_s=remount_time)

            metadata = {"rig": {"kind": "emulator", "sample": sample, "model": parsed.model,
                                "parameters": parsed.parameters, "seed": seed,
                                "min_separation_deg": emulator.min_separation_deg,
                                "realism": realism_metadata(realism, systematics),
                                "lamp_monitor": emulator.monitor is not None,
                                "options": {k: (v if isinstance(v, (bool, int, float, str)) else repr(v))
                                            for k, v in emulator_options.items()},
                                "aperture_sr": [emulator.optics.lamp_solid_angle_sr,
                                                emulator.optics.camera_solid_angle_sr]}}
            yield rig, emulator, change_sample, metadata
        finally:
            rig.close()
    finally:
        emulator.close()


def _progress_printer(quiet: bool):
    if quiet:
        return None
    line = ProgressLine("points")

    def show(p: acquisition.Progress) -> None:
        extra = f"instrument {p.instrument_time / 60:.1f} min"
        if p.refused or p.errors:
            extra += f", {p.refused} refused, {p.errors} failed"
        line.update(p.done, p.total, p.eta_wall, extra)

    return show


def check_ports(ports: dict[str, str | None]) -> None:
    """Refuse a partial set of real-rig ports, or a port path that does not exist.

    Parameters
    ----------
    ports : dict
        ``{"--stage": ..., "--camera": ..., "--lamp": ...}``: device paths (e.g.
        /dev/ttyUSB0), pyserial URLs (``socket://host:port``) or port names (COM3).

    Raises
    ------
    CLIError
        Naming the argument.
    """
    given = [value for value in ports.values() if value]
    if given and len(given) != len(ports):
        raise CLIError("a real rig needs all three of --stage, --camera and --lamp")
    for argument, port in ports.items():
        if port and "://" not in port and "/" in port and not Path(port).exists():
            raise CLIError(f"{argument} {port}: no such serial port (expected an existing device such as "
                           "/dev/ttyUSB0, or a pyserial URL such as socket://host:port)")


def emulated_sample(cli_sample: str | None, protocol: protocols.Protocol) -> str:
    """The sample the emulated rig mounts: ``--sample``, else the protocol's ``[sample]
    emulated``, else :data:`DEFAULT_SAMPLE`. An empty ``--sample`` is refused, not read as
    "not given"."""
    if cli_sample is not None and not cli_sample.strip():
        raise CLIError(f"--sample {cli_sample!r}: expected a sample spec ({SPEC_SYNTAX}), e.g. {DEFAULT_SAMPLE}")
    return cli_sample or protocol.emulated or DEFAULT_SAMPLE


#: Exit status of a run that ended with failed points (docs/acquisition.md).
EXIT_INCOMPLETE = 3


@contextmanager
def _stop_signals_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP (a ``kill``, a closed terminal or session) end a run as Ctrl-C does:
    the recording is marked "interrupted" and the resume command printed, where the
    default action killed the process with the recording still "running". Outside the
    main thread (no signal handlers there) nothing changes."""
    import signal
    import threading

    def interrupt(signum, frame):
        raise KeyboardInterrupt(signal.Signals(signum).name)

    wanted = [getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)]
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, interrupt) for signum in wanted}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _run(args: argparse.Namespace) -> int:
    from gonio import acquisition, protocols

    check_output_folder(args.out, "recording")
    check_ports({"--stage": args.stage, "--camera": args.camera, "--lamp": args.lamp})
    _check_lamp_voltage(args.lamp_voltage, emulated=not all((args.stage, args.camera, args.lamp)))
    protocol = protocols.load(args.protocol)
    settings = adaptive_settings(args, protocol)
    protocol, extend = _adaptive_start(args, protocol, settings)
    ports = (args.stage, args.camera, args.lamp)
    reflectance = protocol.reference.reflectance if protocol.reference else None
    try:
        with _stop_signals_interrupt():
            result = _measure(args, protocol, ports, reflectance, extend,
                              {"adaptive": settings.to_json()} if settings else {})
    except KeyboardInterrupt:
        print(f"\ngonio run: interrupted; everything measured is in {args.out}. "
              f"Continue with: gonio run {args.protocol} --out {args.out} --resume")
        return 130
    except acquisition.AcquisitionError as error:
        raise CLIError(f"{error} (everything measured so far is in {args.out}; resume with --resume)") from error
    print(result.summary())
    if not result.status_recorded:
        print(f"gonio run: {result.messages[-1]}. Free some space, then record the status with: gonio run "
              f"{args.protocol} --out {args.out} --resume", file=sys.stderr)
        return EXIT_INCOMPLETE
    if result.status == "incomplete":
        print(f"gonio run: {result.errors} point(s) failed (their messages are in {args.out}/points.csv); "
              f"measure them again with: gonio run {args.protocol} --out {args.out} --resume", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0


def _check_lamp_voltage(voltage: float, emulated: bool) -> None:
    """Refuse a lamp voltage no supply takes, naming the option: at least a finite value > 0,
    and for the emulated rig at most its supply's largest setpoint (a real supply refuses
    what it cannot give, and the run then stops with the supply's own message)."""
    from drivers.emulator.lamp import LampParams

    if not (math.isfinite(voltage) and voltage > 0):
        raise CLIError(f"--lamp-voltage {voltage:g}: expected a lamp voltage > 0 V")
    supply = LampParams()
    if emulated and voltage > supply.max_voltage_v:
        raise CLIError(f"--lamp-voltage {voltage:g}: the emulated lamp supply gives at most {supply.max_voltage_v:g} V "
                       f"(its nominal voltage is {supply.nominal_voltage_v:g} V)")


def adaptive_settings(args: argparse.Namespace, protocol) -> "adaptive.AdaptiveSettings | None":
    """The adaptive run's settings from the command line (None: not adaptive); the
    adaptive options without ``--adaptive``, or a protocol an adaptive run cannot grow,
    are refused naming them."""
    given = [option for attribute, option in _ADAPTIVE_OPTIONS if getattr(args, attribute) not in (None, [])]
    if not args.adaptive:
        if given:
            raise CLIError(f"{', '.join(given)}: options of an adaptive run; add --adaptive")
        return None
    missing = [option for attribute, option in _ADAPTIVE_OPTIONS[:3] if not getattr(args, attribute)]
    if missing:
        raise CLIError(f"--adaptive needs {', '.join(missing)} (e.g. --model oren-nayar --until sigma=0.5 "
                       "--budget 600s)")
    from gonio import adaptive, models

    try:
        spec = models.get(args.model)
    except (KeyError, ValueError) as error:
        raise CLIError(f"--model {args.model}: {str(error).strip(chr(39))}") from None
    fixed = {name: number(name, value, "--fix") for name, value in name_value_pairs(args.fix, "--fix").items()}
    ranges = prior_ranges(args.prior)
    unknown = sorted((set(ranges) | set(fixed)) - set(spec.param_names))
    if unknown:
        raise CLIError(f"--prior/--fix {unknown}: not parameters of {spec.name}; its parameters are "
                       f"{list(spec.param_names)}")
    priors = {p.name: ranges.get(p.name, p.bounds) for p in spec.params if p.name not in fixed}
    if protocol.mountings.count > 1:
        raise CLIError(f"{protocol.source}: mounts the sample {protocol.mountings.count} times; an adaptive run "
                       "takes a protocol with one mounting")
    calibration = args.calibration or "per-incidence"
    if calibration == "per-incidence" and protocol.reference is None:
        raise CLIError(f"{protocol.source}: reads no reference standard, so the fit cannot calibrate per incidence; "
                       "give --calibration common")
    try:
        return adaptive.AdaptiveSettings(
            spec.name, {n: number(n, v, "--until") for n, v in name_value_pairs(args.until, "--until").items()},
            parse_duration(args.budget), priors, fixed,
            parse_duration(args.batch, "--batch") if args.batch else adaptive.DEFAULT_BATCH_SECONDS, calibration,
            () if args.alignment == "none" else (args.alignment or "all"),
            True if args.stray_light is None else args.stray_light,
            max_angle=90.0 if args.max_angle is None else args.max_angle, seed=args.seed)
    except ValueError as error:
        raise CLIError(str(error)) from None


def _adaptive_start(args: argparse.Namespace, protocol, settings):
    """The protocol to measure and the run's ``extend`` callback: for a resumed adaptive run
    the recording's extended protocol; a plain resume of an adaptive recording is refused."""
    from gonio import adaptive
    from gonio.data import read_metadata

    metadata = read_metadata(args.out) if args.resume and (Path(args.out) / "metadata.json").is_file() else {}
    batches = adaptive.appended_batches(metadata)
    if settings is None:
        if batches:
            raise CLIError(f"{args.out}: was run adaptively ({batches} batch(es) appended); resume it with --adaptive "
                           "and its options (--model, --until, --budget)")
        return protocol, None
    if batches:
        try:
            protocol = adaptive.resume_protocol(metadata, protocol)
        except ValueError as error:
            raise CLIError(str(error)) from None
    say = None if args.quiet else (lambda text: print(f"gonio run: {text}", file=sys.stderr, flush=True))
    return protocol, adaptive.AdaptiveRun(args.out, protocol, settings, batches, say)


def _measure(args: argparse.Namespace, protocol, ports, reflectance, extend=None, extra_metadata=None):
    """Run the protocol on the rig at ``ports``, or on the emulated rig; the RunResult.
    ``extend`` and ``extra_metadata``: an adaptive run's callback and settings."""
    from gonio import acquisition

    if all(ports):
        from drivers.rig import Rig

        def prompt(which: str, mounting: acquisition.SampleMounting | None = None) -> None:
            what = f"the reference standard ({protocol.reference.label})" if which == "reference" else "the sample"
            how = f" ({mounting.instruction()})" if mounting is not None else ""
            spin = ", switch the holder's spinner on" if mounting is not None and mounting.spin else ""
            try:
                input(f"Mount {what} on the sample holder{how}{spin}, then press Enter: ")
            except EOFError:
                raise acquisition.AcquisitionError(
                    f"nobody can mount {what}: the prompt's standard input is closed (run gonio run in a terminal "
                    "to answer it)") from None

        with Rig.open(*ports) as rig:
            result = acquisition.run_protocol(
                protocol, rig, args.out, resume=args.resume, lamp_voltage=args.lamp_voltage,
                warm_up=not args.no_warm_up, change_sample=prompt,
                metadata={"rig": {"kind": "hardware", "stage": args.stage, "camera": args.camera, "lamp": args.lamp},
                          **(extra_metadata or {})},
                progress=_progress_printer(args.quiet), extend=extend,
            )
    else:
        options = {"monitor": False} if args.no_monitor else {}
        sample = emulated_sample(args.sample, protocol)
        with emulated_rig(sample, args.seed, realism=args.realism, remount_time=protocol.rig.remount_time,
                          **options) as (rig, emulator, change_sample, metadata):
            if emulator.systematics.is_ideal:
                print(IDEAL_RIG_NOTE)
            result = acquisition.run_protocol(
                protocol, rig, args.out, resume=args.resume, lamp_voltage=args.lamp_voltage,
                warm_up=not args.no_warm_up,
                change_sample=lambda which, **how: change_sample(which, reflectance, **how),
                clock=emulator.control.now, metadata={**metadata, **(extra_metadata or {})},
                progress=_progress_printer(args.quiet), extend=extend,
            )
    return result

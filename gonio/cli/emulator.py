"""``gonio emulator``: run the emulated goniometer with a registered reflectance model, a rendered surface or a
CUReT material as sample."""
from __future__ import annotations

import argparse
import math
import signal
import threading

from gonio.sample_specs import DEFAULT_SAMPLE

from . import CLIError
from .realism import DEFAULT_REALISM, IDEAL_RIG_NOTE, REALISM_HELP, REALISM_SYNTAX, parse_realism
from .samples import SPEC_SYNTAX, parse_sample_spec

DEVICES = ("stage", "camera", "lamp")


def _port_spec(text: str) -> dict[str, int]:
    """Parse ``stage=5001,camera=5002,lamp=5003`` or a base port ``5000`` (-> 5000, 5001, 5002)."""
    text = text.strip()
    if text.isdigit():
        base = int(text)
        ports = {device: base + k for k, device in enumerate(DEVICES)}
    else:
        ports = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            device, eq, value = item.partition("=")
            if not eq or device not in DEVICES or not value.strip().isdigit():
                raise CLIError(f"--tcp-ports: expected BASE or device=PORT,... with devices {DEVICES}, got {item!r}")
            ports[device] = int(value)
    outside = {device: port for device, port in ports.items() if not 1 <= port <= 65535}
    if outside:
        raise CLIError(f"--tcp-ports {text}: TCP ports are 1 to 65535 (a base port takes {len(DEVICES)} in a row: "
                       f"at most {65536 - len(DEVICES)}); got {outside}")
    return ports


def build_rig(args: argparse.Namespace):
    """The :class:`drivers.emulator.rig.EmulatedRig` described by the parsed arguments."""
    from drivers.emulator.rig import EmulatedRig

    sample = parse_sample_spec(args.sample)
    sample.prepare()  # a rendered surface's table: loaded, or rendered now with progress
    return EmulatedRig(
        sample.brdf,
        seed=args.seed,
        clock_mode=clock_mode(args),
        speed=args.speed,
        min_separation_deg=args.min_separation,
        name=args.name,
        lamp_warm=args.lamp_warm,
        monitor=not args.no_monitor,
        systematics=parse_realism(args.realism, args.seed),
    )


def clock_mode(args: argparse.Namespace) -> str:
    """The clock mode asked for: ``--clock`` (default ``wall``), or ``realtime`` for ``--realtime``."""
    if args.realtime and args.clock not in (None, "realtime"):
        raise CLIError(f"--realtime and --clock {args.clock} ask for two clocks; give one "
                       "(--realtime is --clock realtime)")
    if args.realtime:
        return "realtime"
    return args.clock or "wall"


def clock_text(mode: str, speed: float) -> str:
    """The banner's words for the clock, e.g. ``wall clock x1 (jumps while a client waits on the rig)``."""
    if mode == "event":
        return "event clock (time passes only with the instruments' events; reproducible from the seed)"
    if mode == "wall":
        return f"wall clock x{speed:g} (jumps ahead while a client waits on the rig)"
    return f"real-time clock x{speed:g} (hardware timing)"


def format_addresses(addresses: dict[str, dict[str, str]]) -> str:
    """One line per instrument and transport, e.g. ``stage   pty  /dev/pts/3``."""
    lines = []
    for device, entry in addresses.items():
        for kind in ("pty", "tcp", "url"):
            if kind in entry:
                lines.append(f"{device:<7} {kind:<4} {entry[kind]}")
    return "\n".join(lines)


def _side_channels(rig, args: argparse.Namespace):
    """The control server (``--control``) and the traffic log (``--log-traffic``), or None each."""
    from drivers.emulator.control import ControlServer, TrafficLog

    traffic = None
    if args.log_traffic:
        traffic = TrafficLog(args.log_traffic)
        for channel in rig.channels.values():
            channel.traffic = traffic
    control = ControlServer(rig, args.control) if args.control is not None else None
    return control, traffic


def _run(args: argparse.Namespace) -> int:
    if not (args.pty or args.tcp):
        raise CLIError("nothing to serve: enable --pty and/or --tcp")
    if not (args.speed > 0 and math.isfinite(args.speed)):
        raise CLIError(f"--speed {args.speed:g}: expected simulated seconds per wall second, a number > 0 "
                       "(1: real time)")
    if args.control is not None and not 0 <= args.control <= 65535:
        raise CLIError(f"--control {args.control}: expected a TCP port 0..65535 (0: a free one)")
    rig = build_rig(args)
    symlinks = None
    if args.link_dir:
        symlinks = {device: f"{args.link_dir.rstrip('/')}/gonio-{device}" for device in DEVICES}
    tcp_ports = _port_spec(args.tcp_ports) if args.tcp_ports else None
    stop = threading.Event()
    try:
        addresses = rig.start(pty=args.pty, tcp=args.tcp, tcp_ports=tcp_ports, symlinks=symlinks)
    except OSError as error:
        raise CLIError(f"cannot open the emulator's ports: {error}") from error
    try:
        control, traffic = _side_channels(rig, args)
    except OSError as error:
        rig.close()
        raise CLIError(f"cannot open the control port or the traffic log: {error}") from error
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        clock = clock_text(rig.clock.mode, rig.clock.speed)
        print(f"gonio emulator: sample {args.sample}, seed {args.seed}, {clock}, realism {args.realism}")
        if rig.systematics.is_ideal:
            print(IDEAL_RIG_NOTE)
        else:
            print("departures from the ideal rig: "
                  + ", ".join(f"{k}={v:.4g}" for k, v in rig.systematics.to_dict().items()))
        print(format_addresses({d: {k: v for k, v in e.items() if k != "url"} for d, e in addresses.items()}))
        if control is not None:
            print(f"{'control':<7} tcp  127.0.0.1:{control.port}  (JSON lines, docs/emulator.md)")
        if traffic is not None:
            print(f"traffic log: {traffic.path}")
        print("serving; press Ctrl-C to stop", flush=True)
        while not stop.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        if control is not None:
            control.close()
        rig.close()
        if traffic is not None:
            traffic.close()
        print("gonio emulator: stopped", flush=True)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio emulator``."""
    parser = subparsers.add_parser(
        "emulator",
        help="run the emulated goniometer (stage, camera, lamp) on pseudo-terminals / TCP",
        description=(
            "Run the emulated rig with a registered reflectance model, a rendered micro-surface "
            "(surface:kind=..., docs/surfaces.md) or a measured CUReT material "
            "(curet:NUMBER|NAME, docs/curet-samples.md) as the sample. Each "
            "instrument (stage: ESP300 dialect, camera and lamp: SCPI; see docs/protocol.md) "
            "gets a raw pseudo-terminal and/or a TCP port on 127.0.0.1. Serves until "
            "interrupted."
        ),
    )
    parser.add_argument("--sample", default=DEFAULT_SAMPLE, metavar=SPEC_SYNTAX.replace(" or ", "|"),
                        help="sample BRDF, e.g. oren-nayar:sigma=30,rho=0.9, surface:kind=vgrooves,sigma=30,rho=0.9 "
                             "(a rendered surface, docs/surfaces.md) or curet:plaster_a (default "
                             f"{DEFAULT_SAMPLE}, the paper's wall plaster, as for gonio demo and gonio run)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random process (default 0)")
    parser.add_argument("--realism", default=DEFAULT_REALISM, metavar=REALISM_SYNTAX, help=REALISM_HELP)
    parser.add_argument("--clock", choices=("wall", "event", "realtime"), default=None,
                        help="how simulated time passes (docs/emulator.md, 'Time'): wall (default) follows the "
                             "wall clock x --speed and jumps ahead while a client waits on the rig, so sleeping "
                             "and polling clients see the hardware's timing or better; event moves only with "
                             "the instruments' events (reproducible from the seed; a client's sleep does not "
                             "count); realtime answers with hardware timing (waits sleep)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="K",
                        help="simulated seconds per wall second for the wall and realtime clocks (default 1)")
    parser.add_argument("--realtime", action="store_true", help="the same as --clock realtime")
    parser.add_argument("--min-separation", type=float, default=5.0, metavar="DEG",
                        help="minimum camera-lamp angle enforced by the stage [deg] (default 5)")
    parser.add_argument("--pty", action=argparse.BooleanOptionalAction, default=True,
                        help="serve each instrument on a pseudo-terminal (default on)")
    parser.add_argument("--tcp", action=argparse.BooleanOptionalAction, default=False,
                        help="serve each instrument on a TCP port of 127.0.0.1 (default off)")
    parser.add_argument("--tcp-ports", default=None, metavar="BASE|dev=PORT,...",
                        help="TCP ports: a base port (stage, camera, lamp = BASE, BASE+1, BASE+2) or "
                             "stage=...,camera=...,lamp=... (default: free ports)")
    parser.add_argument("--link-dir", default=None, metavar="DIR",
                        help="also create symlinks DIR/gonio-stage, DIR/gonio-camera, DIR/gonio-lamp to the ptys")
    parser.add_argument("--lamp-warm", action="store_true",
                        help="start with the lamp on and warm (default: off, as at power-on)")
    parser.add_argument("--name", default="default", help="rig name for gonio-sim:// URLs (default 'default')")
    parser.add_argument("--no-monitor", action="store_true",
                        help="a camera without the lamp monitor option (MON?); see docs/emulator.md")
    parser.add_argument("--control", type=int, default=None, metavar="PORT",
                        help="serve the rig's control channel on 127.0.0.1:PORT (0: a free port), JSON lines: "
                             "inject faults, let time pass, read the true state from another process "
                             "(docs/emulator.md, 'Control from outside')")
    parser.add_argument("--log-traffic", default=None, metavar="FILE",
                        help="append every line the instruments receive and their replies, with simulated and "
                             "wall time, to FILE (JSON lines)")
    parser.set_defaults(func=_run)

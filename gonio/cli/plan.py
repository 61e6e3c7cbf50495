"""``gonio plan FILE``: dry-run a sweep protocol."""
from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio plan``."""
    parser = subparsers.add_parser(
        "plan",
        help="dry-run a sweep protocol: points, refused points, estimated time",
        description=(
            "Validate a protocol file and print its plan: the number of points, every point "
            "the rig would refuse (travel limits, camera/lamp separation) with the reason, "
            "and the estimated instrument time. Nothing is moved."
        ),
    )
    parser.add_argument("protocol", help="protocol TOML file (see docs/protocols.md)")
    parser.add_argument("--points", action="store_true", help="also list every planned point")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from gonio import protocols  # loaded by the command itself: every gonio command builds this parser

    protocol = protocols.load(args.protocol)
    result = protocols.plan(protocol)
    print(result.summary())
    design = design_notes(protocol.text)
    if design:
        print("how it was designed (gonio design):")
        print("\n".join(f"  {line}" for line in design))
    if args.points:
        print("planned points (index, block, repeat, theta_i, phi_i, view) [deg]:")
        for p in result.points:
            print(f"  {p.index:5d}  {p.block:<32} {p.repeat:3d}  {p.theta_i:7.2f} {p.phi_i:8.2f} {p.view:8.2f}")
    return 0


def design_notes(text: str) -> list[str]:
    """The comment block ``gonio design`` writes at the head of a protocol (how it was
    chosen, the expected widths, the estimated time), without its ``#``; empty for any
    other protocol.

    >>> design_notes("# Designed by gonio design for lambert.\\n# Expected widths: rho 0.01.\\n[protocol]\\n")
    ['Designed by gonio design for lambert.', 'Expected widths: rho 0.01.']
    """
    lines = text.splitlines()
    if not lines or not lines[0].startswith("# Designed by gonio design"):
        return []
    notes = []
    for line in lines:
        if not line.startswith("#"):
            break
        notes.append(line.lstrip("#").strip())
    return notes

"""``gonio models``: list the registered models; ``gonio models plot``: draw BRDF slices."""
from __future__ import annotations

import argparse
from pathlib import Path

from gonio import models
from gonio.sample_specs import parse_model_spec


def format_model_table() -> str:
    """Plain-text table of every registered model with parameters, units and bounds."""
    lines = []
    for name in models.available():
        model = models.get(name)
        lines.append(f"{name}  -  {model.description}")
        lines.append(f"    reference: {model.reference}")
        for p in model.params:
            lines.append(
                f"    {p.name:<10} [{p.unit}]  default {p.default:g}  range {p.range_text()}  {p.description}"
            )
        for o in model.options:
            choices = "|".join(map(str, o.choices))
            lines.append(f"    {o.name:<10} option  default {o.default!r}  one of {choices}  {o.description}")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _run_list(args: argparse.Namespace) -> int:
    print(format_model_table(), end="")
    return 0


def _run_plot(args: argparse.Namespace) -> int:
    from gonio.report.model_plots import plot_slices  # matplotlib only when plotting

    specs = [parse_model_spec(text) for text in args.model]
    out = Path(args.out)
    figure_path = plot_slices(
        specs,
        theta_i=args.theta_i,
        planes=args.plane,
        quantity=args.quantity,
        out=out,
        title=args.title,
    )
    print(f"wrote {figure_path}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio models`` and ``gonio models plot``."""
    parser = subparsers.add_parser(
        "models", help="list reflectance models; 'gonio models plot' draws BRDF slices",
        description="List every registered reflectance model with its parameters, units and bounds.",
    )
    parser.set_defaults(func=_run_list)
    sub = parser.add_subparsers(dest="models_command", metavar="ACTION")
    plot = sub.add_parser(
        "plot",
        help="draw in-plane and out-of-plane slices of one or more models",
        description=(
            "Plot BRDF or radiance slices of models, overlaid. Models are given as "
            "NAME[:key=value,...], e.g. oren-nayar:sigma=30,rho=0.9. Planes: 'in' (plane of "
            "incidence, signed viewing angle, positive on the source side), 'perp' (plane "
            "perpendicular to it), or an azimuth difference in degrees such as 45."
        ),
    )
    plot.add_argument("model", nargs="+", help="model spec NAME[:key=value,...]")
    plot.add_argument("--theta-i", type=float, nargs="+", default=[75.0], help="incidence angle(s) [deg] (default 75)")
    plot.add_argument("--plane", nargs="+", default=["in"], help="'in', 'perp' or azimuth difference [deg] (default in)")
    plot.add_argument(
        "--quantity", choices=("radiance", "brdf", "normalised"), default="radiance",
        help="radiance for unit irradiance (default), BRDF, or radiance normalised to the normal view",
    )
    plot.add_argument("--title", default=None, help="figure title")
    plot.add_argument("--out", default="gonio-slices.png", help="output PNG path (default gonio-slices.png)")
    plot.set_defaults(func=_run_plot)

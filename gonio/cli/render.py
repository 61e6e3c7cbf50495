"""``gonio render``: a shape or a reflectance map rendered with a model (or a fitted result)
beside Lambert of the same albedo (docs/vision.md)."""
from __future__ import annotations

import argparse
import io
import math
from pathlib import Path
from typing import Callable

import numpy as np

from . import CLIError
from .samples import SPEC_SYNTAX, parse_sample_spec

SHAPES = ("sphere", "cylinder", "map")
#: Posterior draws rendered for a fitted result's band (at most).
DEFAULT_DRAWS = 50
#: Extent of the reflectance map in gradient space: p and q in [-MAP_EXTENT, MAP_EXTENT].
MAP_EXTENT = 3.0


def parse_direction(text: str) -> tuple[float, float]:
    """``THETA,PHI`` [deg] (``THETA`` alone: azimuth 0), theta in [0, 90)."""
    parts = [part.strip() for part in text.split(",")]
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2) or not all(math.isfinite(v) for v in values) or not 0.0 <= values[0] < 90.0:
        raise CLIError(f"direction {text!r}: expected THETA[,PHI] in degrees with 0 <= THETA < 90, e.g. 60,0")
    return values[0], values[1] if len(values) == 2 else 0.0


def _fit_brdfs(folder: str, draws: int) -> tuple[Callable, list[Callable], float | None, str]:
    """The fitted material (:func:`gonio.export.material_of`): its BRDF at the posterior
    medians, at up to ``draws`` posterior draws, its albedo parameter and a title."""
    from gonio.export import material_of

    material = material_of(folder, max_draws=draws)
    rows = range(len(material.draws)) if material.draws is not None else ()
    drawn = [lambda ti, pi, tr, pr, k=k: material.draw_brdf(ti, pi, tr, pr, np.array([k]))[0] for k in rows]
    return material.brdf, drawn, material.values.get("rho"), material.source


def _sources(args: argparse.Namespace) -> tuple[Callable, list[Callable], float | None, str]:
    if Path(args.source).is_dir():
        return _fit_brdfs(args.source, args.draws)
    import gonio

    sample = parse_sample_spec(args.source)
    sample.prepare()
    rho = sample.parameters.get("rho")
    if rho is None and sample.model in gonio.models.available():  # the model's default albedo
        rho = next((p.default for p in gonio.models.get(sample.model).params if p.name == "rho"), None)
    return sample.brdf, [], rho, args.source


def _render_shape(args, brdf, drawn, albedo, title, out: Path) -> list[Path]:
    from gonio import vision
    from gonio.report.vision_plots import shape_figure

    normals, mask = (vision.sphere_normals if args.shape == "sphere" else vision.cylinder_normals)(args.size)
    view = vision.direction(*args.view)
    lambert = vision.lambert_brdf(albedo)
    rows, arrays = [], {}
    for k, light in enumerate(args.light):
        source = vision.direction(*light)
        row = {"model": vision.render(brdf, normals, mask, source, view),
               "lambert": vision.render(lambert, normals, mask, source, view)}
        if drawn:
            images = np.stack([vision.render(b, normals, mask, source, view) for b in drawn])
            row["low"], row["high"] = np.percentile(images, [2.5, 97.5], axis=0)
        rows.append(row)
        arrays.update({f"{name}_{k}": image for name, image in row.items()})
    fig = shape_figure(f"{args.shape}: {title}", rows, args.light, albedo)
    arrays |= {"lights_deg": np.array(args.light), "view_deg": np.array(args.view), "normals": normals, "mask": mask}
    return write_figure_and_arrays(fig, arrays, out)


def _render_map(args, brdf, albedo, title, out: Path) -> list[Path]:
    from gonio import vision
    from gonio.report.vision_plots import reflectance_map_figure

    light = args.light[0]
    axis = np.linspace(-MAP_EXTENT, MAP_EXTENT, args.size)
    p, q = np.meshgrid(axis, axis)
    lambert = vision.lambert_brdf(albedo)
    model = vision.reflectance_map(brdf, vision.direction(*light), p, q)
    flat = vision.reflectance_map(lambert, vision.direction(*light), p, q)
    fig = reflectance_map_figure(f"reflectance map: {title}", p, q, model, flat, light, albedo)
    arrays = {"p": p, "q": q, "model": model, "lambert": flat, "light_deg": np.array(light)}
    return write_figure_and_arrays(fig, arrays, out)


def write_figure_and_arrays(fig, arrays: dict, out: Path) -> list[Path]:
    """Write ``PREFIX.png`` (the figure) and ``PREFIX.npz`` (the arrays), each whole or absent."""
    from gonio.files import write_atomic

    png, npz = out.with_name(out.name + ".png"), out.with_name(out.name + ".npz")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    write_atomic(png, buffer.getvalue())
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    write_atomic(npz, buffer.getvalue())
    return [png, npz]


def _run(args: argparse.Namespace) -> int:
    if args.size < 3:
        raise CLIError(f"--size {args.size}: expected at least 3 pixels across")
    if args.draws < 0:
        raise CLIError(f"--draws {args.draws}: expected a number of posterior draws >= 0")
    out = Path(args.out)
    if not out.parent.is_dir():
        raise CLIError(f"--out {args.out}: the folder {out.parent} does not exist")
    args.light = [parse_direction(text) for text in args.light] if args.light else [(0.0, 0.0), (60.0, 0.0)]
    args.view = parse_direction(args.view)
    brdf, drawn, rho, title = _sources(args)
    from gonio.vision import lambert_albedo

    albedo = lambert_albedo(brdf, rho)
    written = (_render_map(args, brdf, albedo, title, out) if args.shape == "map"
               else _render_shape(args, brdf, drawn, albedo, title, out))
    for path in written:
        print(path)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio render``."""
    parser = subparsers.add_parser(
        "render",
        help="render a sphere, a cylinder or a reflectance map with a model or a fit, beside Lambert",
        description=("Render a shape (sphere, cylinder) or a reflectance map in gradient space with a reflectance "
                     "model, a rendered surface, a CUReT material or a fitted result, beside Lambert of the same "
                     "albedo, as in Oren & Nayar's Figs 3, 23-25 (docs/vision.md). Writes PREFIX.png and "
                     "PREFIX.npz (the images)."),
    )
    parser.add_argument("source", metavar=f"{SPEC_SYNTAX.replace(' or ', '|')}|FIT_FOLDER",
                        help="model spec (e.g. oren-nayar:sigma=30,rho=0.9) or a folder written by gonio fit")
    parser.add_argument("--shape", choices=SHAPES, default="sphere", help="what to render (default sphere)")
    parser.add_argument("--light", action="append", metavar="THETA,PHI",
                        help="source direction [deg] from the viewer's axis; repeat for several images "
                             "(default: from the viewer, 0,0, and from the side, 60,0; a map uses the first)")
    parser.add_argument("--view", default="0,0", metavar="THETA,PHI",
                        help="camera direction [deg] (default 0,0: looking down the shape's axis)")
    parser.add_argument("--size", type=int, default=201, help="pixels across (default 201)")
    parser.add_argument("--draws", type=int, default=DEFAULT_DRAWS,
                        help=f"posterior draws rendered for a fit's 95 %% band (default {DEFAULT_DRAWS}; 0: none)")
    parser.add_argument("--out", required=True, metavar="PREFIX", help="output prefix: PREFIX.png and PREFIX.npz")
    parser.set_defaults(func=_run)

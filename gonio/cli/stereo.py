"""``gonio stereo``: orientations recovered by photometric stereo under Lambert's model and
under a rough model (or a fitted result), with their uncertainty and, when the true shape
is known, their angular error (Oren & Nayar section 6.3, Figs 26-27; docs/vision.md)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from . import CLIError
from .render import parse_direction, write_figure_and_arrays
from .samples import SPEC_SYNTAX, parse_sample_spec

#: Default sources: four at 30 deg from the viewer, a quarter turn apart.
DEFAULT_LIGHTS = ((30.0, 0.0), (30.0, 90.0), (30.0, 180.0), (30.0, 270.0))
DEFAULT_DRAWS = 20


def _images_from_file(path: Path) -> dict[str, Any]:
    """Images, sources and (optional) true shape from an ``.npz``: ``images`` (K, H, W)
    and ``lights_deg`` (K, 2), or the ``model_K`` images of ``gonio render``."""
    try:
        data = np.load(path)
    except (OSError, ValueError) as error:
        raise CLIError(f"{path}: not a readable .npz of images ({error})") from None
    if "lights_deg" not in data:
        raise CLIError(f"{path}: no 'lights_deg' (K, 2) array of source directions [deg]; expected 'images' "
                       "(K, H, W) and 'lights_deg', or the output of gonio render --shape sphere|cylinder")
    lights = np.atleast_2d(data["lights_deg"]).astype(float)
    if "images" in data:
        images = np.asarray(data["images"], float)
    else:
        keys = [f"model_{k}" for k in range(len(lights))]
        if not all(key in data for key in keys):
            raise CLIError(f"{path}: expected an 'images' array or {', '.join(keys)} (one image per source)")
        images = np.stack([data[key] for key in keys]).astype(float)
    return {"images": images, "lights": lights, "mask": data["mask"] if "mask" in data else None,
            "normals": data["normals"] if "normals" in data else None, "title": path.name}


def _images_rendered(args: argparse.Namespace) -> dict[str, Any]:
    """Images of a sphere or a cylinder rendered here with a sample spec under ``--light``."""
    from gonio import vision

    sample = parse_sample_spec(args.source)
    sample.prepare()
    normals, mask = (vision.sphere_normals if args.shape == "sphere" else vision.cylinder_normals)(args.size)
    print(f"rendering {len(args.light)} images of a {args.shape} with {args.source}", flush=True)
    images = np.stack([vision.render(sample.brdf, normals, mask, vision.direction(*light)) for light in args.light])
    return {"images": images, "lights": np.array(args.light, float), "mask": mask, "normals": normals,
            "title": f"{args.shape} of {args.source}"}


def _with_noise(scene: dict[str, Any], fraction: float, seed: int) -> float:
    """Add Gaussian noise of ``fraction`` of the brightest value; its standard deviation."""
    sd = fraction * float(np.nanmax(scene["images"]))
    scene["images"] = scene["images"] + np.random.default_rng(seed).normal(0.0, sd, scene["images"].shape)
    return sd


def _recover(scene: dict[str, Any], args: argparse.Namespace, noise_sd: float | None) -> dict[str, Any]:
    from gonio import vision

    from gonio.export import material_of

    common = {"mask": scene["mask"], "noise_sd": noise_sd, "albedo_known": args.albedo_known,
              "in_plane_of": (0.0, 1.0, 0.0) if args.in_plane else None,
              "progress": lambda text: print(text, flush=True)}
    try:
        material = material_of(args.model, max_draws=max(args.draws, 1))
        results = {"Lambert": vision.photometric_stereo(scene["images"], scene["lights"],
                                                        _lambert_of(material) if args.albedo_known or args.in_plane else None,
                                                        **common)}
        results["model"] = vision.photometric_stereo(scene["images"], scene["lights"], material, draws=args.draws,
                                                     **common)
    except ValueError as error:
        raise CLIError(str(error)) from None
    return results


def _lambert_of(material: Any):
    """Lambert's BRDF of the material's albedo (:func:`gonio.vision.lambert_albedo`): the
    comparison of the paper's Figs 26-27 when the albedo is known."""
    from gonio.vision import lambert_albedo, lambert_brdf

    return lambert_brdf(lambert_albedo(material.brdf, material.values.get("rho")))


def _needed(args: argparse.Namespace) -> int:
    """Sources that must light a pixel to fix its normal: one per unknown, at least 2."""
    return max((1 if args.in_plane else 2) + (0 if args.albedo_known else 1), 2)


def _evaluated(scene: dict[str, Any], args: argparse.Namespace) -> np.ndarray:
    """Pixels lit by enough sources to fix a normal (:func:`_needed`)."""
    needed = _needed(args)
    mask = scene["mask"] if scene["mask"] is not None else np.all(np.isfinite(scene["images"]), axis=0)
    return mask & (np.sum(np.nan_to_num(scene["images"]) > 0, axis=0) >= needed)


def _profiles(scene: dict[str, Any], results: dict[str, Any]) -> dict[str, np.ndarray] | None:
    from gonio.vision import height_profile

    if scene["normals"] is None:
        return None
    middle = scene["images"].shape[1] // 2
    spacing = 2.0 / (scene["images"].shape[2] - 1)
    truth = np.where(scene["mask"][middle][:, None], scene["normals"][middle], np.nan)
    return {"true": height_profile(truth, spacing)} | {
        name: height_profile(result.normals[middle], spacing) for name, result in results.items()}


def _report(results: dict[str, Any], scene: dict[str, Any], evaluated: np.ndarray) -> dict[str, Any]:
    from gonio.vision import summary

    figures = {name: summary(result, scene["normals"], evaluated) for name, result in results.items()}
    for name, numbers in figures.items():
        line = f"{name}: {numbers['pixels']} pixels"
        if "mean_error_deg" in numbers:
            line += (f", angular error mean {numbers['mean_error_deg']:.2f} deg, median "
                     f"{numbers['median_error_deg']:.2f}, 95th percentile {numbers['p95_error_deg']:.2f}; "
                     f"95 % regions hold the true normal at {100 * numbers['coverage']:.1f} % of pixels")
        print(line + f"; median 95 % cone {numbers['median_cone_deg']:.2f} deg")
    return figures


def _run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if not out.parent.is_dir():
        raise CLIError(f"--out {args.out}: the folder {out.parent} does not exist")
    if args.draws < 0 or args.size < 3 or (args.add_noise is not None and not args.add_noise > 0):
        raise CLIError("expected --draws >= 0, --size >= 3 and --add-noise > 0 (a fraction of the brightest value)")
    args.light = [parse_direction(text) for text in args.light] if args.light else list(DEFAULT_LIGHTS)
    source = Path(args.source)
    scene = _images_from_file(source) if source.suffix == ".npz" and source.is_file() else _images_rendered(args)
    evaluated = _evaluated(scene, args)  # lit before any noise is added
    noise_sd = args.noise_sd
    if args.add_noise is not None:
        added = _with_noise(scene, args.add_noise, args.seed)
        noise_sd = added if noise_sd is None else noise_sd
    results = _recover(scene, args, noise_sd)
    figures = _report(results, scene, evaluated)
    from gonio.files import write_atomic
    from gonio.report.vision_plots import stereo_figure

    fig = stereo_figure(f"photometric stereo: {scene['title']}, model {args.model}", results, scene["normals"],
                        evaluated, _profiles(scene, results))
    arrays = {f"{key}_{name}": value for name, r in results.items()
              for key, value in (("normals", r.normals), ("cone95_deg", r.cone_deg()), ("scale", r.scale))}
    arrays |= {"evaluated": evaluated, "lights_deg": scene["lights"]}
    written = write_figure_and_arrays(fig, arrays, out)
    record = {"source": args.source, "model": str(args.model), "lights_deg": scene["lights"].tolist(),
              "noise_sd": noise_sd, "added_noise_fraction": args.add_noise, "seed": args.seed,
              "albedo_known": args.albedo_known, "in_plane": args.in_plane,
              "evaluated": f"pixels lit by at least {_needed(args)} sources",
              "results": figures}
    json_path = out.with_name(out.name + ".json")
    write_atomic(json_path, (json.dumps(record, indent=2) + "\n").encode())
    for path in [*written, json_path]:
        print(path)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``gonio stereo``."""
    parser = subparsers.add_parser(
        "stereo",
        help="photometric stereo under Lambert and under a rough model or a fit, with per-pixel uncertainty",
        description=("Recover surface orientations from images under several sources, by Lambertian least squares "
                     "and by inverting a reflectance model (a spec or a fit, whose posterior adds to the "
                     "uncertainty), as in Oren & Nayar's Figs 26-27 (docs/vision.md). SOURCE is an .npz of images "
                     "(gonio render's output, or 'images' (K, H, W) with 'lights_deg' (K, 2) and optionally "
                     "'normals' and 'mask'), or a sample spec rendered here on a sphere or a cylinder. Writes "
                     "PREFIX.png, PREFIX.npz and PREFIX.json."),
    )
    parser.add_argument("source", metavar=f"IMAGES.npz|{SPEC_SYNTAX.replace(' or ', '|')}",
                        help="images to invert, or a spec to render them with (e.g. oren-nayar-exact:sigma=30,rho=0.9)")
    parser.add_argument("--model", required=True, metavar="SPEC|FIT_FOLDER",
                        help="the reflectance to invert: a model spec or a folder written by gonio fit")
    parser.add_argument("--light", action="append", metavar="THETA,PHI",
                        help="source direction [deg] when rendering (repeat; default four at 30 deg, 90 deg apart)")
    parser.add_argument("--shape", choices=("sphere", "cylinder"), default="sphere",
                        help="shape rendered from a spec (default sphere)")
    parser.add_argument("--size", type=int, default=81, help="pixels across when rendering (default 81)")
    parser.add_argument("--add-noise", type=float, metavar="FRACTION",
                        help="add Gaussian noise of this fraction of the brightest value (seeded by --seed)")
    parser.add_argument("--noise-sd", type=float, metavar="SD",
                        help="standard deviation of the image values [radiance]; default: the added noise, or "
                             "estimated from the residuals")
    parser.add_argument("--seed", type=int, default=0, help="seed of the added noise (default 0)")
    parser.add_argument("--albedo-known", action="store_true",
                        help="hold the albedo at the model's instead of fitting it per pixel (allows two sources)")
    parser.add_argument("--in-plane", action="store_true",
                        help="hold the normals perpendicular to the image's vertical axis (a vertical cylinder, the "
                             "paper's vase: two sources then fix the shape with --albedo-known)")
    parser.add_argument("--draws", type=int, default=DEFAULT_DRAWS,
                        help=f"posterior draws of a fit re-inverted for the model's uncertainty (default {DEFAULT_DRAWS})")
    parser.add_argument("--out", required=True, metavar="PREFIX", help="output prefix")
    parser.set_defaults(func=_run)

"""BRDF files other tools read (MERL binary, tidy CSV, ASTM E1392 rows), with their uncertainty.

:func:`export` writes the BRDF of a material, given as a model spec
(``oren-nayar:sigma=30,rho=0.9``) or as a fit result (a folder written by
:meth:`gonio.fitting.FitResult.save`, or the :class:`~gonio.fitting.FitResult` itself),
or, for ``astm``, the measured rows of a recording (a folder written by ``gonio run``),
in one of :data:`FORMATS`:

``merl``
    The binary of the MERL BRDF database (Matusik et al. 2003): a header of three int32
    (90, 90, 180), then 90 x 90 x 180 float64 values per channel, red, then green, then
    blue, in the half/difference-angle parametrisation of Rusinkiewicz (1998). The
    uncertainty goes to a side-car ``FILE.uncertainty.npz`` (:func:`write_merl`).
``csv``
    A tidy table, one row per geometry of a grid (:data:`DEFAULT_GRID`), with the
    posterior's median, 95 % interval and standard deviation of a fit as columns
    (:func:`write_csv`).
``astm``
    Rows in the terms of ASTM E1392: incident angle, scatter polar angle and azimuth,
    BRDF and cosine-corrected BRDF with their standard uncertainty, under a header naming
    the sample, source, receiver, wavelength, polarization and dates (:mod:`gonio.export_astm`,
    :func:`write_astm`, :func:`write_astm_recording`); side-car ``FILE.uncertainty.npz``.

What is exported is the material's BRDF [1/sr]: the fitted model with the material's
parameters only (``rho``, ``sigma``, ...), not the measured quantity of the fit (the
scale of relative radiance, the rig's errors and its apertures belong to the instrument,
not to the sample). The posterior's spread is propagated by evaluating the model at
posterior draws (:data:`MERL_DRAWS`, :data:`CSV_DRAWS`). The full description, with the
sources of the MERL layout: ``docs/export.md``.

References
----------
.. [1] W. Matusik, H. Pfister, M. Brand, L. McMillan, "A data-driven reflectance model",
   ACM Transactions on Graphics 22(3), 2003 (the MERL BRDF database), and its reader
   ``BRDFRead.cpp`` distributed with the database (file layout, index mapping, scale
   factors).
.. [2] S. Rusinkiewicz, "A new change of variables for efficient BRDF representation",
   Eurographics Workshop on Rendering, 1998 (the half/difference angles).
"""
from __future__ import annotations

import json
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from gonio import models
from gonio.export_astm import astm_text, geometry_columns, is_recording, model_header, npz_bytes, recording_rows
from gonio.export_astm import value_columns
from gonio.files import write_atomic
from gonio.sample_specs import parse_model_spec

__all__ = ["export", "FORMATS", "MERL_SHAPE", "MERL_SCALE", "MERL_INVALID", "MERL_DRAWS", "CSV_DRAWS",
           "DEFAULT_GRID", "RANGE_MARGIN_DEG", "Material", "material_of", "merl_geometry", "csv_geometry",
           "parse_grid", "sidecar_path", "write_merl", "write_csv", "write_astm", "write_astm_recording",
           "MERL_WARN_SECONDS", "MERL_VALID_CELLS", "merl_seconds", "merl_time_warning", "SlowExportWarning"]

#: The formats :func:`export` writes.
FORMATS = ("merl", "csv", "astm")
#: Cells of a MERL file: theta_h, theta_d, phi_d.
MERL_SHAPE = (90, 90, 180)
#: The factors a MERL reader multiplies the stored red, green and blue values by.
MERL_SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
#: Cells of a MERL file with both directions above the horizon (:func:`merl_geometry`).
MERL_VALID_CELLS = 1_096_216
#: The stored value of a cell whose incidence or view lies below the horizon (negative:
#: invalid to every MERL reader).
MERL_INVALID = -1.0
#: Posterior draws behind the per-cell standard deviation of a MERL side-car.
MERL_DRAWS = 50
#: Posterior draws behind the quantiles and standard deviation of a CSV row.
CSV_DRAWS = 200
#: The CSV grid: polar angles of incidence and view, azimuth difference [deg].
DEFAULT_GRID: dict[str, np.ndarray] = {
    "theta_i": np.arange(0.0, 85.0 + 1e-9, 5.0),
    "theta_r": np.arange(0.0, 85.0 + 1e-9, 5.0),
    "dphi": np.arange(0.0, 180.0 + 1e-9, 15.0),
}
#: How far beyond the data's polar angles a geometry still counts as within them [deg].
RANGE_MARGIN_DEG = 5.0
#: Geometries evaluated at once for posterior draws (draws x cells of temporaries).
_CHUNK_ELEMENTS = 2**22
#: A MERL export estimated to take longer than this warns before it starts [s].
MERL_WARN_SECONDS = 30.0
#: The time a rate measurement of :func:`merl_seconds` aims at [s].
_TIMING_SECONDS = 0.1


@dataclass
class Material:
    """The BRDF to export: a model, its parameter values and, for a fit, posterior draws.

    Attributes
    ----------
    model : str
        Registered model name.
    values : dict
        The exported values of the model's parameters (a fit: posterior medians).
    options : dict
        Discrete model options.
    draws : ndarray or None
        Posterior draws of the model's parameters, shape (D, len(names)); None without a
        posterior.
    names : tuple of str
        The parameters the columns of ``draws`` hold.
    theta_range : tuple of (float, float), (float, float), or None
        The fitted data's range of incidence and of viewing polar angles [deg]; None
        for a model spec.
    source : str
        What was exported (the spec, or the fit folder and model).
    about : dict
        A fit's provenance: its data's label, quantity and points, the recording it came
        from, when it was made, its id, and whether it converged and is adequate.
    """

    model: str
    values: dict[str, float]
    options: dict[str, Any]
    draws: np.ndarray | None = None
    names: tuple[str, ...] = ()
    theta_range: tuple[tuple[float, float], tuple[float, float]] | None = None
    source: str = ""
    about: dict[str, Any] = field(default_factory=dict)

    def brdf(self, theta_i, phi_i, theta_r, phi_r) -> np.ndarray:
        """The exported values' BRDF [1/sr] at angles [deg]."""
        return models.get(self.model)(theta_i, phi_i, theta_r, phi_r, **self.values, **self.options)

    def draw_brdf(self, theta_i, phi_i, theta_r, phi_r, rows: np.ndarray) -> np.ndarray:
        """The BRDF [1/sr] of the posterior draws ``rows`` (indices into ``draws``) at flat
        angle arrays [deg] of M geometries: shape (len(rows), M)."""
        frozen = models.get(self.model).at(theta_i, phi_i, theta_r, phi_r, **self.options)
        columns = {name: self.draws[rows, k][:, None] for k, name in enumerate(self.names)}
        out = frozen(**dict(self.values, **columns))
        return np.broadcast_to(out, (len(rows), np.size(theta_i)))


def material_of(source: Any, max_draws: int = CSV_DRAWS, seed: int = 0) -> Material:
    """The material a source names: a model spec, a fit folder or a FitResult.

    Parameters
    ----------
    source : str, path or FitResult
        ``MODEL[:key=value,...]`` (parameters not given take their defaults), a folder
        holding a saved fit (``result.json``), or a :class:`gonio.fitting.FitResult`.
    max_draws : int
        Most posterior draws kept (drawn without replacement, ``seed``).
    seed : int
        Seed of the choice of draws.

    Raises
    ------
    ValueError
        An unknown model, a bad parameter, or a path that is neither a fit folder nor a
        spec, naming what was wrong.
    """
    if not isinstance(source, (str, os.PathLike)):
        return _material_of_fit(source, max_draws, seed, str(getattr(source, "model", "fit")))
    text = os.fspath(source)
    if Path(text).is_dir():
        from gonio.fitting import FitResult

        if is_recording(text) and not (Path(text) / "result.json").is_file():
            raise ValueError(f"{text} is a recording (gonio run), not a model or a fit: --format astm exports its "
                             f"measured rows; merl and csv export a model or a fit (fit it first: gonio fit {text})")
        if not (Path(text) / "result.json").is_file():
            raise ValueError(f"{text}: a folder that is neither a fit result (no result.json) nor a recording (no "
                             "metadata.json and points.csv); expected a fit folder (gonio fit --out), a recording "
                             "folder (gonio run --out, astm only) or a model spec MODEL[:key=value,...]")
        return _material_of_fit(FitResult.load(text), max_draws, seed, text)
    try:
        name, values = parse_model_spec(text)
    except ValueError as error:
        if ":" not in text and text.strip() not in models.available():
            raise ValueError(f"{error}; {text!r} is not a fit folder either (no such folder)") from None
        raise
    model = models.get(name)
    numbers, options = model.resolve(values)
    return Material(name, dict(numbers), dict(options), source=text)


def _material_of_fit(result: Any, max_draws: int, seed: int, where: str) -> Material:
    """:func:`material_of` for a FitResult: the model's parameters at the posterior medians
    (least-squares values without a chain), at most ``max_draws`` posterior draws."""
    model = models.get(result.model)
    best = dict(result.fixed, **result.best_values())
    values = {name: float(best[name]) for name in model.param_names if name in best}
    names = tuple(name for name in result.free if name in model.param_names)
    samples = result.samples()
    draws = None
    if samples.shape[0] and names:
        rows = np.random.default_rng(seed).choice(samples.shape[0], min(max_draws, samples.shape[0]), replace=False)
        draws = samples[np.sort(rows)][:, [result.free.index(name) for name in names]]
    data = result.dataset
    theta_range = ((float(np.min(data.theta_i)), float(np.max(data.theta_i))),
                   (float(np.min(data.theta_r)), float(np.max(data.theta_r))))
    about = {"label": data.label, "quantity": data.quantity, "points": int(data.n),
             "recording": data.metadata.get("recording"), "created": result.created, "result_id": result.result_id,
             "converged": result.converged, "adequate": result.adequate}
    return Material(model.name, values, dict(result.options), draws, names, theta_range,
                    source=f"fit {where} ({model.name})", about=about)


def within_data(material: Material, theta_i, theta_r, margin: float = RANGE_MARGIN_DEG) -> np.ndarray:
    """Whether geometries lie within the angular range of the fitted data.

    A geometry is within when its incidence lies in the data's range of incidence
    angles and its view in the data's range of viewing angles, each widened by
    ``margin`` [deg] on both sides, or the same with incidence and view exchanged (the
    models are reciprocal). Everything is within for a material without data.

    Parameters
    ----------
    material : Material
    theta_i, theta_r : array_like
        Polar angles of incidence and view [deg].
    margin : float
        Widening of the data's ranges [deg].

    Returns
    -------
    ndarray of bool
    """
    theta_i, theta_r = np.broadcast_arrays(np.asarray(theta_i, float), np.asarray(theta_r, float))
    if material.theta_range is None:
        return np.ones(theta_i.shape, bool)
    (lo_i, hi_i), (lo_r, hi_r) = material.theta_range

    def inside(angle: np.ndarray, lo: float, hi: float) -> np.ndarray:
        return (angle >= lo - margin) & (angle <= hi + margin)

    direct = inside(theta_i, lo_i, hi_i) & inside(theta_r, lo_r, hi_r)
    return direct | (inside(theta_r, lo_i, hi_i) & inside(theta_i, lo_r, hi_r))


# ---------------------------------------------------------------------- MERL geometry
def merl_geometry(cells: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """The incidence and view [deg] of every MERL cell (or of ``cells``), and which lie
    above the horizon.

    Cell (i, j, k) is sampled at its centre in index space:
    theta_h = ((i + 0.5) / 90)^2 * 90 deg, theta_d = j + 0.5 deg, phi_d = k + 0.5 deg,
    with phi_h = 0 (isotropic materials). The MERL reader's lookup (index =
    floor(sqrt(theta_h / 90 deg) * 90), floor(theta_d), floor(phi_d)) maps this point back
    to (i, j, k), away from any cell edge.

    Parameters
    ----------
    cells : array of int, optional
        Flat indices of cells in file order; all cells when None.

    Returns
    -------
    theta_i, phi_i, theta_r, phi_r : ndarray
        Flat arrays of 1,458,000 angles [deg] in file order (phi_d fastest, then
        theta_d, then theta_h), or one per index of ``cells``.
    valid : ndarray of bool
        Both directions strictly above the horizon.

    Notes
    -----
    Rusinkiewicz's inverse change of variables: the incoming direction is the
    difference vector d = (sin theta_d cos phi_d, sin theta_d sin phi_d, cos theta_d)
    rotated by theta_h about y (and phi_h about z), the outgoing one its mirror image
    about the half vector h = (sin theta_h, 0, cos theta_h): w_o = 2 (w_i . h) h - w_i.
    """
    i, j, k = np.ogrid[:MERL_SHAPE[0], :MERL_SHAPE[1], :MERL_SHAPE[2]] if cells is None else \
        np.unravel_index(np.asarray(cells, int), MERL_SHAPE)
    theta_h = np.radians(((i + 0.5) / MERL_SHAPE[0]) ** 2 * 90.0)
    theta_d, phi_d = np.radians(j + 0.5), np.radians(k + 0.5)
    dx, dy, dz = np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)
    ch, sh = np.cos(theta_h), np.sin(theta_h)
    wi = np.broadcast_arrays(dx * ch + dz * sh, dy, -dx * sh + dz * ch)
    cos_d = np.cos(theta_d)
    wo = [2.0 * cos_d * h - w for h, w in zip((sh, 0.0, ch), wi)]
    valid = ((wi[2] > 0) & (wo[2] > 0)).reshape(-1)
    theta_i, phi_i = _polar(wi)
    theta_r, phi_r = _polar(wo)
    return theta_i, phi_i, theta_r, phi_r, valid


def _polar(w: list[np.ndarray] | tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle and azimuth [deg] of unit vectors given by components, flattened."""
    x, y, z = (np.reshape(c, -1) for c in w)
    return np.degrees(np.arccos(np.clip(z, -1.0, 1.0))), np.degrees(np.arctan2(y, x))


# ---------------------------------------------------------------------- CSV geometry
def parse_grid(items: Mapping[str, Any] | None) -> dict[str, np.ndarray]:
    """The CSV grid: :data:`DEFAULT_GRID` with the axes ``items`` names replaced.

    Parameters
    ----------
    items : mapping, optional
        ``theta_i``, ``theta_r`` (polar angles [deg], 0-90) and ``dphi`` (azimuth
        difference [deg]), each an array of values or text ``START:STOP:STEP`` (STOP
        included) or a single number.

    Raises
    ------
    ValueError
        An unknown axis, text that is not a range, an empty axis or a polar angle
        outside [0, 90], naming the axis.
    """
    grid = dict(DEFAULT_GRID)
    for name, value in (items or {}).items():
        if name not in DEFAULT_GRID:
            raise ValueError(f"grid axis {name!r} is unknown; expected one of {', '.join(DEFAULT_GRID)}")
        values = _grid_axis(name, value) if isinstance(value, str) else np.atleast_1d(np.asarray(value, float))
        if values.size == 0 or not np.isfinite(values).all():
            raise ValueError(f"grid axis {name}: expected finite values [deg], got {value!r}")
        if name != "dphi" and ((values < 0) | (values > 90)).any():
            raise ValueError(f"grid axis {name} = {value!r}: polar angles must lie in [0, 90] deg")
        grid[name] = values
    return grid


def _grid_axis(name: str, text: str) -> np.ndarray:
    """``START:STOP:STEP`` (STOP included) or one number, as an array [deg]."""
    parts = text.split(":")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"grid axis {name}={text!r}: expected START:STOP:STEP in deg, e.g. 0:85:5") from None
    if len(numbers) == 1:
        return np.array(numbers)
    if len(numbers) != 3 or numbers[2] <= 0 or numbers[1] < numbers[0]:
        raise ValueError(f"grid axis {name}={text!r}: expected START:STOP:STEP with STOP >= START and STEP > 0")
    start, stop, step = numbers
    return start + step * np.arange(int(math.floor((stop - start) / step + 1e-9)) + 1)


def csv_geometry(grid: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flat angles [deg] of the CSV rows: theta_i slowest, then theta_r, then dphi;
    phi_i = 0 and phi_r = dphi."""
    ti, tr, dphi = np.meshgrid(grid["theta_i"], grid["theta_r"], grid["dphi"], indexing="ij")
    return ti.ravel(), np.zeros(ti.size), tr.ravel(), dphi.ravel()


# ---------------------------------------------------------------------- posterior
def _draw_statistics(material: Material, geometry: tuple[np.ndarray, ...], quantiles: bool,
                     progress: Callable[[int, int], None] | None) -> dict[str, np.ndarray]:
    """Posterior standard deviation (and median, 2.5/97.5 % quantiles) of the BRDF [1/sr]
    over the material's draws at flat geometries, in chunks of cells."""
    n_draws = material.draws.shape[0]
    rows = np.arange(n_draws)
    size = geometry[0].size
    chunk = max(1, _CHUNK_ELEMENTS // n_draws)
    keys = ("sd", "median", "p2_5", "p97_5") if quantiles else ("sd",)
    out = {key: np.empty(size) for key in keys}
    for start in range(0, size, chunk):
        part = slice(start, min(size, start + chunk))
        values = material.draw_brdf(*(a[part] for a in geometry), rows)
        out["sd"][part] = values.std(axis=0, ddof=1) if n_draws > 1 else 0.0
        if quantiles:
            out["p2_5"][part], out["median"][part], out["p97_5"][part] = np.percentile(values, [2.5, 50, 97.5], axis=0)
        if progress is not None:
            progress(part.stop, size)
    return out


# ---------------------------------------------------------------------- writers
def sidecar_path(out: str | Path) -> Path:
    """The uncertainty side-car of a MERL file: ``FILE.uncertainty.npz`` beside it."""
    out = Path(out)
    return out.with_name(out.name + ".uncertainty.npz")


def merl_bytes(brdf: np.ndarray, valid: np.ndarray) -> bytes:
    """A grey BRDF [1/sr] of every cell (flat, file order) as a MERL file's bytes.

    Each channel holds ``brdf`` divided by its factor of :data:`MERL_SCALE`, so that a
    reader gets the same value in all three; invalid cells hold :data:`MERL_INVALID`.
    Little-endian int32 header and float64 values, as the database's files.
    """
    header = np.array(MERL_SHAPE, "<i4").tobytes()
    channels = [np.where(valid, brdf / scale, MERL_INVALID).astype("<f8").tobytes() for scale in MERL_SCALE]
    return header + b"".join(channels)


def write_merl(material: Material, out: Path, draws: int = MERL_DRAWS,
               progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write ``out`` (MERL binary) and its side-car ``out.uncertainty.npz``.

    The side-car (numpy ``.npz``, arrays of shape (90, 90, 180) indexed like the MERL
    cells, [theta_h, theta_d, phi_d]): ``valid`` (both directions above the horizon),
    ``within_data`` (:func:`within_data` of the cell's incidence and view; all True for a
    model spec), ``has_posterior`` (a bool scalar), ``n_draws``, ``margin_deg``,
    ``theta_range_deg`` (a fit: [[min, max] of incidence], [min, max] of view]), ``sd``
    (with a posterior only: the BRDF's posterior standard deviation [1/sr], 0 in invalid
    cells), and ``description`` (JSON text: source, model, values, units, the choices).

    Returns
    -------
    list of Path
        The files written, MERL file first.
    """
    say = progress or (lambda message: None)
    say(f"evaluating {material.model} at {np.prod(MERL_SHAPE):,} MERL cells")
    ti, pi_, tr, pr, valid = merl_geometry()
    brdf = np.zeros(ti.size)
    brdf[valid] = _in_chunks(material.brdf, tuple(a[valid] for a in (ti, pi_, tr, pr)), _percent(say))
    arrays: dict[str, Any] = {"valid": valid.reshape(MERL_SHAPE),
                              "within_data": (within_data(material, ti, tr) & valid).reshape(MERL_SHAPE)}
    if material.draws is not None:
        n = min(draws, material.draws.shape[0])
        subset = Material(**dict(vars(material), draws=material.draws[:n]))
        say(f"posterior standard deviation over {n} draws")
        sd = np.zeros(ti.size)
        flat = tuple(a[valid] for a in (ti, pi_, tr, pr))
        sd[valid] = _draw_statistics(subset, flat, False, _percent(say))["sd"]
        arrays["sd"] = sd.reshape(MERL_SHAPE)
    arrays.update(_sidecar_fields(material, draws))
    side = sidecar_path(out)
    write_atomic(out, merl_bytes(brdf, valid))
    write_atomic(side, npz_bytes(arrays))
    return [out, side]


def _in_chunks(function: Callable[..., np.ndarray], geometry: tuple[np.ndarray, ...],
               progress: Callable[[int, int], None]) -> np.ndarray:
    """``function`` of flat angle arrays [deg], evaluated :data:`_CHUNK_ELEMENTS` // 8
    geometries at a time (progress for slow models)."""
    size = geometry[0].size
    chunk = _CHUNK_ELEMENTS // 8
    out = np.empty(size)
    for start in range(0, size, chunk):
        part = slice(start, min(size, start + chunk))
        out[part] = function(*(a[part] for a in geometry))
        progress(part.stop, size)
    return out


def _percent(say: Callable[[str], None]) -> Callable[[int, int], None]:
    """A chunk counter that reports every further 10 % through ``say``."""
    reached = [0]

    def report(done: int, total: int) -> None:
        tenth = 10 * done // total
        if tenth > reached[0]:
            reached[0] = tenth
            say(f"  {10 * tenth} % of cells")

    return report


#: What a side-car's ``sample_point`` says, by the format it belongs to.
_SAMPLE_POINTS = {
    "merl": "cell centre in index space: theta_h = ((i + 0.5)/90)^2 90 deg, theta_d = j + 0.5 deg, phi_d = k + 0.5 "
            "deg, phi_h = 0",
    "astm": "the row's angles: theta_i, phi_i, theta_s, phi_s of the ASTM file, row by row",
}


def _sidecar_fields(material: Material, draws: int, layout: str = "merl") -> dict[str, Any]:
    """The side-car's scalar fields and its JSON description (``layout``: the format it
    belongs to, a key of :data:`_SAMPLE_POINTS`)."""
    n = 0 if material.draws is None else min(draws, material.draws.shape[0])
    description = {
        "format": f"gonio-{layout}-uncertainty", "source": material.source, "model": material.model,
        "values": material.values, "options": material.options, "brdf_unit": "1/sr",
        "has_posterior": material.draws is not None, "n_draws": n,
        "theta_range_deg": material.theta_range, "margin_deg": RANGE_MARGIN_DEG,
        "sample_point": _SAMPLE_POINTS[layout],
        "sd": "posterior standard deviation of the BRDF [1/sr]" if n else "absent: no posterior (a model spec or a "
              "least-squares fit); the values are exact for the model and parameters named",
    }
    return {"has_posterior": np.bool_(n > 0), "n_draws": np.int64(n), "margin_deg": np.float64(RANGE_MARGIN_DEG),
            "theta_range_deg": np.array(material.theta_range if material.theta_range else np.full((2, 2), np.nan)),
            "description": np.array(json.dumps(description))}


def write_csv(material: Material, out: Path, grid: Mapping[str, Any] | None = None,
              progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write the tidy CSV table ``out``: one row per geometry of ``grid`` (:func:`parse_grid`).

    Lines starting with ``#`` first (``# key: JSON value``: format, source, model, values,
    units, grid, draws, data range), then a header row and the rows. Columns: ``theta_i``,
    ``phi_i``, ``theta_r``, ``phi_r`` [deg], ``brdf`` [1/sr] at the exported values; with a
    posterior also ``brdf_median``, ``brdf_p2_5``, ``brdf_p97_5``, ``brdf_sd`` [1/sr] over
    the draws; for a fit ``within_data`` (1 or 0, :func:`within_data`).
    """
    say = progress or (lambda message: None)
    axes = parse_grid(grid)
    geometry = csv_geometry(axes)
    say(f"evaluating {material.model} at {geometry[0].size:,} geometries")
    columns = {"theta_i": geometry[0], "phi_i": geometry[1], "theta_r": geometry[2], "phi_r": geometry[3],
               "brdf": material.brdf(*geometry)}
    if material.draws is not None:
        stats = _draw_statistics(material, geometry, True, None)
        columns.update({f"brdf_{key}": stats[key] for key in ("median", "p2_5", "p97_5", "sd")})
    if material.theta_range is not None:
        columns["within_data"] = within_data(material, geometry[0], geometry[2]).astype(int)
    header = {"format": "gonio-brdf-export", "source": material.source, "model": material.model,
              "values": material.values, "options": material.options, "angle_unit": "deg", "brdf_unit": "1/sr",
              "grid": {k: v.tolist() for k, v in axes.items()}, "phi_i": 0.0, "phi_r": "dphi",
              "n_draws": 0 if material.draws is None else int(material.draws.shape[0]),
              "theta_range_deg": material.theta_range, "margin_deg": RANGE_MARGIN_DEG}
    lines = [f"# {key}: {json.dumps(value)}" for key, value in header.items()]
    lines.append(",".join(columns))
    table = np.column_stack(list(columns.values()))
    lines += [",".join(_cell(name, v) for name, v in zip(columns, row)) for row in table]
    write_atomic(out, "\n".join(lines) + "\n")
    return [out]


def _cell(name: str, value: float) -> str:
    """One CSV cell: integers for the within_data flag, 17 significant digits otherwise."""
    return str(int(value)) if name == "within_data" else repr(float(value))


def write_astm(material: Material, out: Path, grid: Mapping[str, Any] | None = None,
               progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write ASTM E1392 rows of a model spec or a fit on ``grid`` (:func:`parse_grid`), and
    the side-car ``out.uncertainty.npz``.

    Columns (:mod:`gonio.export_astm`): ``theta_i``, ``phi_i``, ``theta_s``, ``phi_s``
    [deg], ``brdf`` [1/sr] (with a posterior its median over the draws, else the model at
    the exported values), ``u_brdf`` (with a posterior: its standard deviation over the
    draws), ``cc_brdf`` and ``u_cc_brdf`` (times cos theta_s), and for a fit
    ``within_data`` (:func:`within_data`). The side-car holds, in row order,
    ``brdf_at_values`` (the model at the exported values) and with a posterior ``median``,
    ``sd``, ``p2_5`` and ``p97_5`` [1/sr], with the fields of a MERL side-car
    (``has_posterior``, ``n_draws``, ``theta_range_deg``, ``margin_deg``, ``description``).

    Returns
    -------
    list of Path
        The rows, then the side-car.
    """
    say = progress or (lambda message: None)
    axes = parse_grid(grid)
    geometry = csv_geometry(axes)
    say(f"evaluating {material.model} at {geometry[0].size:,} geometries")
    arrays: dict[str, Any] = {"brdf_at_values": material.brdf(*geometry)}
    brdf, sd = arrays["brdf_at_values"], None
    if material.draws is not None:
        stats = _draw_statistics(material, geometry, True, None)
        arrays.update(stats)
        brdf, sd = stats["median"], stats["sd"]
    columns = geometry_columns(*geometry)
    columns.update(value_columns(brdf, sd, columns["theta_s"]))
    if material.theta_range is not None:
        columns["within_data"] = within_data(material, geometry[0], geometry[2]).astype(int)
        arrays["within_data"] = columns["within_data"].astype(bool)
    n = 0 if material.draws is None else int(material.draws.shape[0])
    side = sidecar_path(out)
    arrays.update(_sidecar_fields(material, n, "astm"))
    write_atomic(out, astm_text(model_header(material, axes, n, side.name), columns))
    write_atomic(side, npz_bytes(arrays))
    return [out, side]


def write_astm_recording(folder: str | Path, out: Path, progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write ASTM E1392 rows of a recording's measured geometries, and the side-car.

    The rows and the header come from :func:`gonio.export_astm.recording_rows` (the
    recording reduced as ``gonio reduce --brdf`` does); the side-car
    ``out.uncertainty.npz`` holds the values' ``covariance`` [1/sr^2] and every component
    ``u_<name>`` of ``u_brdf`` [1/sr].

    Returns
    -------
    list of Path
        The rows, then the side-car.
    """
    (progress or (lambda message: None))(f"reducing the recording {folder}")
    side = sidecar_path(out)
    header, columns, arrays = recording_rows(folder, side.name)
    write_atomic(out, astm_text(header, columns))
    write_atomic(side, npz_bytes(arrays))
    return [out, side]


# ---------------------------------------------------------------------- MERL time
def merl_seconds(material: Material, draws: int = MERL_DRAWS) -> float:
    """Estimated time [s] of a MERL export of ``material`` with ``draws`` posterior draws.

    The model (and, with a posterior, the draws) is timed on up to 4096 valid MERL cells
    (the valid ones among 8192 cells evenly spaced in file order), in batches that double
    until one takes :data:`_TIMING_SECONDS`, after one small untimed batch (tables and
    compiled code load once per process); the rate is extrapolated to the
    :data:`MERL_VALID_CELLS` valid cells.

    Returns
    -------
    float
        Seconds; a rough figure (within a factor of about 2), enough to warn.
    """
    *angles, valid = merl_geometry(np.linspace(0, np.prod(MERL_SHAPE) - 1, 8192).astype(int))
    geometry = tuple(a[valid][:4096] for a in angles)
    total = _seconds_per_cell(material.brdf, geometry) * MERL_VALID_CELLS
    if material.draws is not None:
        rows = np.arange(min(draws, material.draws.shape[0]))
        total += _seconds_per_cell(lambda *g: material.draw_brdf(*g, rows), geometry) * MERL_VALID_CELLS
    return total


def _seconds_per_cell(function: Callable[..., np.ndarray], geometry: tuple[np.ndarray, ...]) -> float:
    """Seconds per geometry of ``function`` of flat angle arrays [deg] (see :func:`merl_seconds`)."""
    function(*(a[:8] for a in geometry))
    n = 16
    while True:
        start = time.perf_counter()
        function(*(a[:n] for a in geometry))
        elapsed = time.perf_counter() - start
        if elapsed >= _TIMING_SECONDS or n >= geometry[0].size:
            return elapsed / n
        n = min(2 * n, geometry[0].size)


def merl_time_warning(material: Material, draws: int = MERL_DRAWS) -> str | None:
    """The warning a MERL export of ``material`` gives before it starts, or None when it is
    estimated to take at most :data:`MERL_WARN_SECONDS` (:func:`merl_seconds`)."""
    seconds = merl_seconds(material, draws)
    if seconds <= MERL_WARN_SECONDS:
        return None
    hint = (" Export its table instead: oren-nayar-tabulated (same parameters), which takes seconds."
            if material.model == "oren-nayar-exact" else "")
    with_draws = f" with {min(draws, material.draws.shape[0])} posterior draws" if material.draws is not None else ""
    return (f"a MERL export of {material.model}{with_draws} is estimated to take about {_duration(seconds)} (its "
            f"{MERL_VALID_CELLS:,} cells above the horizon at the rate measured just now).{hint}")


def _duration(seconds: float) -> str:
    """``seconds`` as a rounded duration in s, minutes or hours."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} minutes"
    return f"{seconds / 3600:.1f} hours"


# ---------------------------------------------------------------------- entry point
def check_out(out: str | Path, overwrite: bool = False) -> Path:
    """The output path, refused when its folder is missing or it exists (unless ``overwrite``)."""
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"output {out}: its folder {out.parent} does not exist; create it first")
    if out.is_dir():
        raise ValueError(f"output {out} is a folder; expected a file name")
    if out.exists() and not overwrite:
        raise ValueError(f"output {out} exists; choose another name or pass overwrite=True (--overwrite)")
    return out


class SlowExportWarning(UserWarning):
    """An export estimated to take longer than :data:`MERL_WARN_SECONDS`."""


def export(source: Any, format: str, out: str | Path, grid: Mapping[str, Any] | None = None,
           draws: int | None = None, overwrite: bool = False, seed: int = 0,
           progress: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None) -> list[Path]:
    """Write the BRDF of a model spec, a fit or (astm) a recording in a format other tools read.

    Parameters
    ----------
    source : str, path or FitResult
        A model spec ``MODEL[:key=value,...]`` (e.g. ``oren-nayar:sigma=30,rho=0.9``), a
        fit folder (``gonio fit --out``) or a :class:`gonio.fitting.FitResult`; for
        ``astm`` also a recording folder (``gonio run --out``).
    format : {'merl', 'csv', 'astm'}
        See the module docstring and ``docs/export.md``.
    out : path
        The file to write; its folder must exist. MERL and ASTM exports also write
        ``out.uncertainty.npz`` (:func:`write_merl`, :func:`write_astm`).
    grid : mapping, optional
        CSV and ASTM of a spec or a fit: axes replacing those of :data:`DEFAULT_GRID`
        (:func:`parse_grid`).
    draws : int, optional
        Most posterior draws used (default :data:`MERL_DRAWS` for merl, :data:`CSV_DRAWS`
        for csv and astm).
    overwrite : bool
        Replace existing files.
    seed : int
        Seed of the choice of posterior draws.
    progress : callable, optional
        Called with a line of text at each stage of long work.
    warn : callable, optional
        Called with the warning of a MERL export estimated to take longer than
        :data:`MERL_WARN_SECONDS` (:func:`merl_time_warning`), before it starts; without
        it the warning is a :class:`SlowExportWarning`.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        Unknown format, unknown model, bad parameter, a grid for merl or a recording, a
        folder that is neither a fit nor a recording, a recording without a reference
        standard, an output folder that does not exist or a file that exists, naming what
        was wrong.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> [p.name for p in export("lambert:rho=0.5", "csv", folder / "lambert.csv")]
    ['lambert.csv']
    """
    _check_request(source, format, grid, draws)
    paths = [check_out(out, overwrite)]
    if format != "csv":
        paths.append(check_out(sidecar_path(out), overwrite))
    if format == "astm" and _is_recording_source(source):
        return write_astm_recording(source, paths[0], progress)
    count = draws if draws is not None else (MERL_DRAWS if format == "merl" else CSV_DRAWS)
    material = material_of(source, count, seed)
    if format == "merl":
        message = merl_time_warning(material, count)
        if message is not None and warn is not None:
            warn(message)
        elif message is not None:
            warnings.warn(message, SlowExportWarning, stacklevel=2)
        return write_merl(material, paths[0], count, progress)
    if format == "astm":
        return write_astm(material, paths[0], grid, progress)
    return write_csv(material, paths[0], grid, progress)


def _is_recording_source(source: Any) -> bool:
    """Whether ``source`` names a recording folder (and not a fit folder)."""
    return (isinstance(source, (str, os.PathLike)) and is_recording(source)
            and not (Path(source) / "result.json").is_file())


def _check_request(source: Any, format: str, grid: Mapping[str, Any] | None, draws: int | None) -> None:
    """Refuse an unknown format, a grid for merl or a recording, and too few draws."""
    if format not in FORMATS:
        raise ValueError(f"format {format!r} is unknown; expected one of {', '.join(FORMATS)}")
    if format == "merl" and grid is not None:
        raise ValueError("grid: the MERL format has its own fixed grid; a grid applies to csv and astm only")
    if format == "astm" and _is_recording_source(source) and (grid is not None or draws is not None):
        raise ValueError(f"{os.fspath(source)} is a recording: its rows are its measured geometries; grid and draws "
                         "apply to model specs and fits only")
    if draws is not None and draws < 2:
        raise ValueError(f"draws = {draws}: expected at least 2 posterior draws for a standard deviation")

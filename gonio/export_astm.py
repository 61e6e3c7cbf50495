"""ASTM E1392 rows of scattered gonio data: a model's, a fit's or a recording's BRDF.

The practice (ASTM E1392-96, reapproved 2002; withdrawn by ASTM in 2003 and continued by
SEMI as ME1392) describes the measurement of the BRDF of opaque surfaces, with E1392's
names for the geometry: the incident angle theta_i, and the scatter polar angle theta_s and
azimuth phi_s, phi_s = 0 on the specular side of the plane of incidence and 180 deg on the
source's side. This module builds what :func:`gonio.export.export` writes for
``format="astm"``: a header of ``# key: value`` lines (JSON values), a line of column
names, then one comma-separated row per geometry; ``docs/export.md`` ("ASTM E1392 rows")
describes the layout, and why each header item is there.

Nothing here writes files: :mod:`gonio.export` evaluates models and fits on its grid and
writes; this module names the columns, the header items and a recording's rows.

References
----------
.. [1] ASTM E1392-96(2002), "Standard Practice for Angle Resolved Optical Scatter
   Measurements on Specular or Diffuse Surfaces", ASTM International (withdrawn 2003,
   transferred to SEMI: SEMI ME1392).
.. [2] J. C. Stover, "Optical Scattering: Measurement and Analysis", SPIE Press (the
   BRDF, the cosine-corrected BRDF and the angle convention of the scatter literature).
"""
from __future__ import annotations

import io
import json
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from gonio.files import json_default

__all__ = ["ASTM_FORMAT", "PRACTICE", "UNITS", "INTEGER_COLUMNS", "RECORDING_FILES", "scatter_azimuth",
           "is_recording", "geometry_columns", "value_columns", "astm_text", "model_header", "recording_rows",
           "npz_bytes"]

#: The ``# format:`` line of an ASTM export.
ASTM_FORMAT = "gonio astm-e1392 1"
#: The practice the rows follow.
PRACTICE = ("ASTM E1392-96(2002) Standard Practice for Angle Resolved Optical Scatter Measurements on Specular or "
            "Diffuse Surfaces (withdrawn by ASTM 2003, continued by SEMI as ME1392)")
#: The unit of every column an export may hold, in the order of the columns.
UNITS = {"theta_i": "deg", "phi_i": "deg", "theta_s": "deg", "phi_s": "deg", "brdf": "1/sr", "u_brdf": "1/sr",
         "cc_brdf": "1/sr", "u_cc_brdf": "1/sr", "within_data": "1", "repeats": "1", "low_signal": "1"}
#: Columns written as integers (flags and counts).
INTEGER_COLUMNS = ("within_data", "repeats", "low_signal")
#: The files that make a folder a recording of ``gonio run``.
RECORDING_FILES = ("metadata.json", "points.csv")

ANGLES = ("theta_i: polar angle of incidence from the sample normal; phi_i: azimuth of the incidence in the "
          "sample's frame (the sample's orientation); theta_s: scatter polar angle from the normal; phi_s: scatter "
          "azimuth from the plane of incidence, 0 on its specular side and 180 on the source's side, in (-180, "
          "180]; in gonio's angles phi_s = phi_r - phi_i - 180 deg")
BRDF_DEFINITION = ("brdf = (P_s / Omega_s) / (P_i cos theta_s): scattered power per unit solid angle over incident "
                   "power, per cosine of the scatter polar angle [1/sr]")
CC_BRDF_DEFINITION = "cc_brdf = brdf cos(theta_s) = (P_s / Omega_s) / P_i, the cosine-corrected BRDF [1/sr]"
MODEL_POLARIZATION = ("unpolarized: gonio's models give the BRDF of unpolarized light (Fresnel terms averaged over "
                      "the s and p polarizations)")
EMULATOR_POLARIZATION = ("unpolarized source, polarization-insensitive receiver: the emulated rig (an incandescent "
                         "lamp, a CCD camera without polarizer) models no polarization")
HARDWARE_POLARIZATION = "not recorded: a recording holds no polarizer setting; state the rig's"
IDEAL_RIG = "IDEALISED emulated rig (--realism ideal): a study option, not a real lab's rig"


def scatter_azimuth(phi_i, phi_r) -> np.ndarray:
    """E1392's scatter azimuth phi_s [deg] of gonio's azimuths of incidence and view [deg].

    phi_s is measured from the plane of incidence: 0 on its specular side (gonio's
    phi_r = phi_i + 180 deg), 180 deg on the source's side (phi_r = phi_i), in (-180, 180].

    Examples
    --------
    >>> scatter_azimuth([0.0, 0.0, 0.0], [180.0, 0.0, 90.0]).tolist()
    [0.0, 180.0, -90.0]
    """
    d = np.mod(np.asarray(phi_r, float) - np.asarray(phi_i, float) - 180.0, 360.0)
    return np.where(d > 180.0, d - 360.0, d)


def is_recording(path: str | Path) -> bool:
    """Whether ``path`` is a recording folder of ``gonio run`` (:data:`RECORDING_FILES`)."""
    return Path(path).is_dir() and all((Path(path) / name).is_file() for name in RECORDING_FILES)


def geometry_columns(theta_i, phi_i, theta_r, phi_r) -> dict[str, np.ndarray]:
    """The angle columns [deg] of gonio's angles: theta_i, phi_i, theta_s (= theta_r), phi_s."""
    theta_i, phi_i, theta_r, phi_r = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r,
                                                                                          phi_r)))
    return {"theta_i": theta_i, "phi_i": phi_i, "theta_s": theta_r, "phi_s": scatter_azimuth(phi_i, phi_r)}


def value_columns(brdf: np.ndarray, sigma: np.ndarray | None, theta_s: np.ndarray) -> dict[str, np.ndarray]:
    """The value columns: ``brdf``, ``u_brdf`` (with ``sigma``), ``cc_brdf`` and ``u_cc_brdf``
    [1/sr]; the cosine correction multiplies by cos(theta_s) [theta_s in deg]."""
    cos_s = np.cos(np.radians(theta_s))
    out = {"brdf": np.asarray(brdf, float)}
    if sigma is not None:
        out["u_brdf"] = np.asarray(sigma, float)
    out["cc_brdf"] = out["brdf"] * cos_s
    if sigma is not None:
        out["u_cc_brdf"] = out["u_brdf"] * cos_s
    return out


def astm_text(header: Mapping[str, Any], columns: Mapping[str, np.ndarray]) -> str:
    """The file's text: ``# key: JSON`` lines (``header``, then ``columns``, ``units`` and
    ``rows``), the column names, one comma-separated row per geometry.

    Floats are written with 17 significant digits (``repr``), the columns of
    :data:`INTEGER_COLUMNS` as integers.
    """
    names = list(columns)
    items = dict(header, columns=names, units=[UNITS[name] for name in names],
                 rows=int(np.size(columns[names[0]])))
    lines = [f"# {key}: {json.dumps(value, default=json_default)}" for key, value in items.items()]
    lines.append(",".join(names))
    cells = [[str(int(v)) for v in columns[n]] if n in INTEGER_COLUMNS else [repr(float(v)) for v in columns[n]]
             for n in names]
    lines += [",".join(row) for row in zip(*cells)]
    return "\n".join(lines) + "\n"


def npz_bytes(arrays: Mapping[str, Any]) -> bytes:
    """An uncompressed ``.npz`` archive of ``arrays`` as bytes (to be written atomically)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _software() -> str:
    import gonio

    return f"gonio {gonio.__version__}"


# ---------------------------------------------------------------------- models and fits
def model_header(material: Any, grid: Mapping[str, np.ndarray], n_draws: int, sidecar: str) -> dict[str, Any]:
    """The header items of a model spec's or a fit's rows (a :class:`gonio.export.Material`).

    Parameters
    ----------
    material : gonio.export.Material
    grid : mapping
        The grid's axes [deg] (``theta_i``, ``theta_r``, ``dphi``).
    n_draws : int
        Posterior draws behind ``brdf`` and ``u_brdf`` (0: the model at its values).
    sidecar : str
        The side-car's file name.
    """
    fit = material.theta_range is not None
    about = dict(getattr(material, "about", {}) or {})
    header = {
        "format": ASTM_FORMAT, "practice": PRACTICE, "data": "fit" if fit else "model", "measured": False,
        "note": ("rows of a model on a grid, not measurements: E1392 infers nothing at angles or wavelengths that "
                 "were not measured" + ("; rows with within_data = 0 lie outside the fitted data's angles "
                                        "(extrapolations)" if fit else "")),
        "sample": about.get("label") if fit else "none: a model spec",
        "source": material.source, "model": material.model, "values": material.values, "options": material.options,
        "quantity": "BRDF", "brdf_definition": BRDF_DEFINITION, "cc_brdf_definition": CC_BRDF_DEFINITION,
        "brdf_column": (f"the posterior median of the BRDF over {n_draws} draws of the parameters" if n_draws else
                        "the model at the fit's least-squares values" if fit else "the model at the values named"),
        "uncertainty": (f"u_brdf: posterior standard deviation of the BRDF over {n_draws} draws (a standard "
                        "uncertainty, k = 1); quantiles in the side-car" if n_draws else
                        "none: " + ("a fit without a posterior (least squares)" if fit else
                                   "a model spec is exact for the model and values named")),
        "angles": ANGLES, "angle_unit": "deg",
        "grid": {"theta_i": grid["theta_i"], "theta_s": grid["theta_r"], "phi_i": [0.0],
                 "phi_s": np.unique(scatter_azimuth(0.0, grid["dphi"]))},
        "wavelength_nm": None,
        "wavelength": "none: the model is grey; it holds at the wavelength its parameters describe",
        "polarization": MODEL_POLARIZATION,
        "incident_beam": "collimated (the BRDF at a point: no average over a source's solid angle)",
        "receiver": "a point receiver (no average over a receiver's solid angle)",
    }
    if fit:
        header.update(fit=about, theta_range_deg=material.theta_range)
    header.update(exported=_now(), software=_software(), sidecar=sidecar)
    return header


# ---------------------------------------------------------------------- recordings
def recording_rows(folder: str | Path, sidecar: str) -> tuple[dict[str, Any], dict[str, np.ndarray],
                                                                dict[str, Any]]:
    """The header, the columns and the side-car's arrays of a recording's measured rows.

    The recording is reduced as ``gonio reduce --brdf`` does (the default lamp handling
    and linearity correction, one calibration ``E_0`` by the reference standard): one row
    per measured geometry, repeats combined, at the geometry the stage read back.

    Parameters
    ----------
    folder : path
        A recording folder of ``gonio run``.
    sidecar : str
        The side-car's file name (named in the header).

    Returns
    -------
    header : dict
    columns : dict of ndarray
        theta_i, phi_i, theta_s, phi_s [deg], brdf, u_brdf, cc_brdf, u_cc_brdf [1/sr],
        repeats, low_signal.
    arrays : dict
        The side-car: ``covariance`` of the brdf values [1/sr^2], every uncertainty
        component ``u_<name>`` [1/sr], ``flags``, ``description`` (JSON).

    Raises
    ------
    ValueError
        A recording without a reference standard (no absolute BRDF), or one the
        reduction refuses, naming the folder and why.
    """
    from gonio.data import read_metadata
    from gonio.reduction import reduce_recording

    folder = Path(folder)
    reduced = reduce_recording(folder)
    if reduced.reference_irradiance is None:
        raise ValueError(f"{folder}: the recording has no reference standard (its protocol has no [reference] table, "
                         "or its readings were not measured): its values are relative radiance, not BRDF, and "
                         "--format astm exports calibrated BRDF only (gonio reduce gives the relative values)")
    data, components = reduced.brdf_components("common")
    columns = geometry_columns(data.theta_i, data.phi_i, data.theta_r, data.phi_r)
    columns.update(value_columns(data.value, data.sigma, data.theta_r))
    flags = np.asarray(reduced.flags if reduced.flags is not None else [""] * data.n, str)
    columns.update(repeats=np.asarray(reduced.repeats, int), low_signal=(flags == "low_signal").astype(int))
    header = _recording_header(folder, read_metadata(folder), reduced, sidecar)
    arrays = {"covariance": np.asarray(data.covariance, float), "flags": flags,
              **{f"u_{name}": np.asarray(values, float) for name, values in components.items()},
              "description": np.array(json.dumps({"format": "gonio-astm-uncertainty", "data": "measured",
                                                  "source": str(folder), "unit": "1/sr",
                                                  "covariance": "covariance of the brdf values in row order [1/sr^2]",
                                                  "components": [f"u_{n}" for n in components]}))}
    return header, columns, arrays


def _recording_header(folder: Path, meta: Mapping[str, Any], reduced: Any, sidecar: str) -> dict[str, Any]:
    """The header items of a recording's rows: sample, source, receiver, instrument, dates."""
    instruments = meta.get("experiment", {}).get("instruments", {})
    aperture = reduced.metadata.get("aperture_sr") or [None, None]
    wavelength, band = _wavelength(meta)
    return {
        "format": ASTM_FORMAT, "practice": PRACTICE, "data": "measured", "measured": True,
        "note": "one row per measured geometry, repeats combined, at the geometry the stage read back",
        "sample": _sample(meta, reduced), "source": str(folder), "protocol": meta.get("protocol", {}).get("name"),
        "quantity": "BRDF", "brdf_definition": BRDF_DEFINITION, "cc_brdf_definition": CC_BRDF_DEFINITION,
        "brdf_column": ("the BRDF of each measured geometry, calibrated by the reference standard (gonio reduce "
                        "--brdf, one lamp irradiance E_0 for every value)"),
        "uncertainty": ("u_brdf: standard uncertainty (k = 1) of each value from the reduction's budget, the "
                        "calibration included; the errors values share (covariance) and every component are in "
                        "the side-car"),
        "angles": ANGLES, "angle_unit": "deg",
        "wavelength_nm": wavelength, "wavelength": band, "polarization": _polarization(meta),
        "incident_beam": {"source": instruments.get("lamp"), "lamp_voltage_v": meta.get("lamp_voltage"),
                          "solid_angle_sr": aperture[0]},
        "receiver": {"detector": instruments.get("camera"), "solid_angle_sr": aperture[1],
                     "linearity_corrected": "linearity" in reduced.budget},
        "instrument": _instrument(meta, instruments),
        "reference_standard": _reference(meta, reduced),
        "measured_at": {"started": meta.get("started"), "finished": meta.get("finished"),
                        "status": meta.get("status")},
        "excluded": dict(reduced.excluded), "warnings": list(reduced.warnings),
        "exported": _now(), "software": _software(), "recorded_with": meta.get("software"), "sidecar": sidecar,
    }


def _sample(meta: Mapping[str, Any], reduced: Any) -> dict[str, Any]:
    """Sample identification: label, the protocol's sample metadata, the emulated sample."""
    sample = meta.get("sample", {})
    out = {"label": reduced.label, "metadata": sample.get("metadata") or {}}
    rig = meta.get("rig", {})
    if rig.get("kind") == "emulator":
        out["emulated"] = {"spec": rig.get("sample"), "parameters": rig.get("parameters")}
    return out


def _instrument(meta: Mapping[str, Any], instruments: Mapping[str, Any]) -> dict[str, Any]:
    """The rig: kind, stage, and for the emulator its realism (an idealised rig named as such)."""
    rig = meta.get("rig", {})
    out = {"rig": rig.get("kind"), "stage": instruments.get("stage"),
           "encoder_resolution_deg": meta.get("stage", {}).get("encoder_resolution_deg")}
    if rig.get("kind") == "emulator":
        spec = str((rig.get("realism") or {}).get("spec", ""))
        out["realism"] = spec
        if spec.split(":")[0] == "ideal":
            out["note"] = IDEAL_RIG
    return out


def _wavelength(meta: Mapping[str, Any]) -> tuple[float | None, str]:
    """Wavelength [nm] (None when unknown) and how it is known."""
    if meta.get("rig", {}).get("kind") != "emulator":
        return None, "not recorded: a recording holds no wavelength or band; state the rig's filter and source"
    from drivers.emulator.world import Optics

    centre = float(Optics().wavelength_nm)
    return centre, (f"the emulated camera's band, centred at {centre:g} nm (drivers.emulator.world.Optics; not "
                    "stored in the recording): the emulated sample is grey, the band sets photon counts only")


def _polarization(meta: Mapping[str, Any]) -> str:
    return EMULATOR_POLARIZATION if meta.get("rig", {}).get("kind") == "emulator" else HARDWARE_POLARIZATION


def _reference(meta: Mapping[str, Any], reduced: Any) -> dict[str, Any]:
    """The reference standard that calibrates the BRDF, and the calibration's uncertainty."""
    from gonio.protocols import loads

    out: dict[str, Any] = {}
    text = meta.get("protocol", {}).get("text")
    standard = loads(text).reference if text else None
    if standard is not None:
        out.update(label=standard.label, reflectance=standard.reflectance,
                   reflectance_uncertainty=standard.reflectance_uncertainty)
    out["irradiance_relative_sigma"] = reduced.reference_irradiance_sigma / reduced.reference_irradiance
    out["calibration_budget"] = dict(reduced.calibration)
    return out

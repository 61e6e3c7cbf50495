"""The calibrated BRDF of a reduced recording as a table a user opens: ``brdf.csv``.

One row per value: the readback geometry [deg], the absolute BRDF [1/sr], its standard
uncertainty and every component of it, the number of measurements combined and the
value's flags. Header lines ``# key: value`` carry plain JSON values (numbers, strings,
lists, objects), never program text. The covariance of the values (texture, mountings,
PRNU, the linearity correction and the calibration are shared between values) goes beside
the table as ``brdf_covariance.npy``, which the header names; ``gonio fit brdf.csv`` and
:meth:`gonio.fitting.Dataset.from_csv` read it back with the table. Columns and header
keys: docs/data-format.md, "The calibrated BRDF table".
"""
from __future__ import annotations

import csv
import io
import json
from typing import Any, Iterable, Mapping

import numpy as np

from ..files import json_default

__all__ = ["BRDF_FORMAT", "BRDF_TABLE", "BRDF_COVARIANCE", "brdf_table_text", "csv_text", "header_lines"]

#: The ``# format:`` line of a ``brdf.csv``.
BRDF_FORMAT = "gonio brdf 1"
#: The calibrated BRDF table and its covariance (``gonio reduce --brdf``, ``Reduced.write``).
BRDF_TABLE, BRDF_COVARIANCE = "brdf.csv", "brdf_covariance.npy"


def csv_text(rows: list[Mapping[str, Any]]) -> str:
    """Rows of equal keys as CSV text; floats written in full (``repr``)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (repr(float(v)) if isinstance(v, (float, np.floating)) else v) for k, v in r.items()}
                     for r in rows)
    return buffer.getvalue()


def header_lines(header: Mapping[str, Any]) -> str:
    """``# key: JSON`` lines, one per entry (values must be JSON-serialisable).

    >>> print(header_lines({"unit": "1/sr", "calibration": {"certificate": 0.002}}), end="")
    # unit: "1/sr"
    # calibration: {"certificate": 0.002}
    """
    return "".join(f"# {key}: {json.dumps(value, default=json_default)}\n" for key, value in header.items())


def brdf_table_text(reduced: Any, calibration: str = "common") -> tuple[str, np.ndarray]:
    """``brdf.csv``'s text and the values' covariance [1/sr^2] for ``reduced``.

    Parameters
    ----------
    reduced : gonio.reduction.Reduced
        A reduced recording with a reference standard.
    calibration : {"common", "per-incidence"}
        One lamp irradiance for every value, or the standard's at each lamp polar angle
        (:meth:`Reduced.brdf`).

    Raises
    ------
    ValueError
        No reference standard, or (per incidence) a lamp polar angle without one.
    """
    data, components = reduced.brdf_components(calibration)
    header = {
        "format": BRDF_FORMAT,
        "quantity": "brdf",
        "unit": "1/sr",
        "label": reduced.label,
        "recording": reduced.metadata.get("recording"),
        "calibration": calibration,
        "reference_irradiance": reduced.reference_irradiance,
        "reference_irradiance_relative_sigma": reduced.reference_irradiance_sigma / reduced.reference_irradiance,
        "calibration_budget": dict(reduced.calibration),
        "covariance": BRDF_COVARIANCE,
        "components": [f"u_{name}" for name in components],
        "excluded": dict(reduced.excluded),
        "warnings": list(reduced.warnings),
    }
    rows = list(_rows(reduced, data, components))
    return header_lines(header) + csv_text(rows), np.asarray(data.covariance, float)


def _rows(reduced: Any, data, components: Mapping[str, np.ndarray]) -> Iterable[dict[str, Any]]:
    for k in range(data.n):
        row: dict[str, Any] = {"theta_i": data.theta_i[k], "phi_i": data.phi_i[k], "theta_r": data.theta_r[k],
                               "phi_r": data.phi_r[k], "view": reduced.view[k], "value": data.value[k],
                               "sigma": data.sigma[k]}
        row.update({f"u_{name}": values[k] for name, values in components.items()})
        row.update(repeats=int(reduced.repeats[k]), flags=str(reduced.flags[k]) if reduced.flags is not None else "")
        yield row

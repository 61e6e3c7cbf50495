"""Measured reflectance data as the fitting code sees it: :class:`Dataset`.

A dataset is a set of measurements at known geometries, each with a value and its
one-standard-deviation uncertainty, plus the *quantity* the values are:

``'brdf'``
    Absolute BRDF f_r [1/sr] (a calibrated instrument).
``'normalised_radiance'``
    L_r(theta_r) / L_r(0): the radiance divided by the radiance seen from the normal
    direction at the same incidence, as Oren & Nayar (1995) plot their measurements
    (section 5, Figs 16-22).  For a fixed source this equals f_r(theta_r) / f_r(0), so the
    model prediction is the BRDF at the measured geometry divided by the BRDF at the normal
    view (theta_r = 0) of the same incidence [-].
``'radiance'``
    Relative radiance in arbitrary (but consistent) units: the model prediction is
    ``scale * f_r * cos(theta_i)`` with a free parameter ``scale`` (irradiance times the
    camera's gain) [data units sr].

The CSV form has one header line ``theta_i,phi_i,theta_r,phi_r,value,sigma`` (angles in
degrees), optionally preceded by ``# key: value`` lines (``quantity``, ``label`` and any
metadata).
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from gonio.geometry import azimuth_difference, signed_viewing_angle

from .covariance import LowRankCovariance

__all__ = ["Dataset", "QUANTITIES", "CSV_COLUMNS", "QUANTITY_LABELS"]

#: Quantities a dataset can hold, with the unit of the values.
QUANTITIES = {"brdf": "1/sr", "normalised_radiance": "-", "radiance": "arbitrary units"}

#: Axis labels for plots and reports.
QUANTITY_LABELS = {
    "brdf": "BRDF f_r [1/sr]",
    "normalised_radiance": "normalised radiance L_r / L_r(0) [-]",
    "radiance": "relative radiance [arb. units]",
}

#: Columns of the CSV data format, in order.
CSV_COLUMNS = ("theta_i", "phi_i", "theta_r", "phi_r", "value", "sigma")

_ANGLE_FIELDS = ("theta_i", "phi_i", "theta_r", "phi_r")
#: Metadata entries with one item per value (a subset keeps its values' items): the
#: planned lamp polar angle whose reference readings calibrated each value
#: (gonio.reduction, a calibration per incidence).
PER_VALUE_METADATA = ("incidence_theta_i",)
# Two measurements belong to the same incidence when their source angles agree to this
# tolerance [deg]; a manual source set-up (Oren & Nayar section 5) is repeatable to far
# better than a tenth of a degree in the recorded value.
_INCIDENCE_TOLERANCE_DEG = 0.05
# A viewing direction lies in the plane of incidence when its azimuth differs from the
# source's by 0 or 180 deg to this tolerance [deg] (or when theta_r = 0).
_PLANE_TOLERANCE_DEG = 0.5


def _as_vector(name: str, value: Any, n: int | None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"Dataset field {name!r} must be numeric, got {value!r:.80}") from None
    if array.ndim == 0 and n is not None:
        array = np.full(n, float(array))
    if array.ndim != 1:
        raise ValueError(f"Dataset field {name!r} must be one-dimensional, got shape {array.shape}")
    if n is not None and array.shape[0] != n:
        raise ValueError(
            f"Dataset field {name!r} has {array.shape[0]} entries but 'value' has {n}; "
            "every field must have one entry per measurement (or be a scalar)"
        )
    bad = ~np.isfinite(array)
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"Dataset field {name!r} entry {index} is {array[index]!r}; NaN and infinite "
            "values are not allowed (drop the measurement instead)"
        )
    return array


@dataclass(frozen=True, eq=False)
class Dataset:
    """Reflectance measurements at known geometries, with uncertainties.

    Parameters
    ----------
    theta_i, phi_i : array_like
        Source polar angle [deg] in [0, 90] and azimuth [deg], one per measurement (or a
        scalar shared by all).
    theta_r, phi_r : array_like
        Viewing polar angle [deg] in [0, 90] and azimuth [deg].
    value : array_like
        Measured values (1-D, at least one), in the unit of ``quantity``.
    sigma : array_like
        One-standard-deviation uncertainty of each value (> 0), same unit.
    quantity : {'brdf', 'normalised_radiance', 'radiance'}
        What ``value`` holds (see the module docstring for the model prediction of each).
    label : str
        Short name of the sample or run, used in reports.
    metadata : dict
        Free-form information (instrument, date, protocol...); saved with fit results.
    covariance : array_like or LowRankCovariance, optional
        Covariance matrix of the measurement errors, shape (n, n), when they are
        correlated (a reduced recording: the PRNU of nested camera windows, the
        normal-view value shared by an incidence's normalised values, the calibration of
        absolute BRDF), or the same as a diagonal plus low rank
        (:class:`gonio.fitting.covariance.LowRankCovariance`, what a reduction gives: the
        fit then never forms the n x n matrix). Its diagonal must equal ``sigma**2``. Fits
        then use the generalised least-squares likelihood
        (:class:`gonio.fitting.FitProblem`). Saved beside fit results and CSV tables in
        numpy's formats.

    Raises
    ------
    ValueError
        Naming the field: wrong shape, non-numeric, NaN or infinite entries, polar angles
        outside [0, 90] deg, uncertainties that are not strictly positive, unknown quantity.

    Examples
    --------
    >>> data = Dataset(theta_i=30, phi_i=0, theta_r=[0, 20, 40], phi_r=0,
    ...                value=[0.30, 0.29, 0.27], sigma=0.01)
    >>> data.n, data.quantity
    (3, 'brdf')
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    quantity: str = "brdf"
    label: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)
    covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        value = _as_vector("value", self.value, None)
        if value.size == 0:
            raise ValueError("Dataset field 'value' is empty; a dataset needs at least one measurement")
        n = value.size
        arrays = {"value": value}
        for name in (*_ANGLE_FIELDS, "sigma"):
            arrays[name] = _as_vector(name, getattr(self, name), n)
        for name in ("theta_i", "theta_r"):
            outside = (arrays[name] < 0.0) | (arrays[name] > 90.0)
            if outside.any():
                index = int(np.flatnonzero(outside)[0])
                raise ValueError(
                    f"Dataset field {name!r} entry {index} = {arrays[name][index]:g} deg is "
                    "outside [0, 90] deg (polar angles are measured from the surface normal)"
                )
        not_positive = arrays["sigma"] <= 0.0
        if not_positive.any():
            index = int(np.flatnonzero(not_positive)[0])
            raise ValueError(
                f"Dataset field 'sigma' entry {index} = {arrays['sigma'][index]:g} must be > 0: "
                "it is the one-standard-deviation uncertainty of the value"
            )
        if self.quantity not in QUANTITIES:
            raise ValueError(
                f"Dataset field 'quantity' = {self.quantity!r} is not one of {list(QUANTITIES)}"
            )
        for name, array in arrays.items():
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        if self.covariance is not None:
            object.__setattr__(self, "covariance", _checked_covariance(self.covariance, arrays["sigma"]))
        object.__setattr__(self, "label", str(self.label))
        object.__setattr__(self, "metadata", dict(self.metadata))

    # ------------------------------------------------------------------ derived views
    @property
    def n(self) -> int:
        """Number of measurements."""
        return int(self.value.size)

    @property
    def unit(self) -> str:
        """Unit of ``value`` and ``sigma``."""
        return QUANTITIES[self.quantity]

    @property
    def geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(theta_i, phi_i, theta_r, phi_r) [deg]."""
        return self.theta_i, self.phi_i, self.theta_r, self.phi_r

    @property
    def azimuth_difference(self) -> np.ndarray:
        """phi_r - phi_i wrapped to (-180, 180] [deg]."""
        return azimuth_difference(self.phi_i, self.phi_r)

    @property
    def in_plane(self) -> np.ndarray:
        """True where the viewer lies in the plane of incidence (or on the normal)."""
        sin_offset = np.abs(np.sin(np.radians(self.azimuth_difference)))
        tolerance = math.sin(math.radians(_PLANE_TOLERANCE_DEG))
        return (sin_offset <= tolerance) | (self.theta_r == 0.0)

    @property
    def signed_view(self) -> np.ndarray:
        """Signed in-plane viewing angle [deg], positive on the source side (DESIGN.md)."""
        return signed_viewing_angle(self.theta_r, self.phi_r, self.phi_i)

    def incidences(self) -> tuple[np.ndarray, np.ndarray]:
        """Distinct source directions and the index of each measurement's one.

        Returns
        -------
        sources : ndarray, shape (k, 2)
            (theta_i, phi_i) [deg] of each distinct incidence, sorted.
        index : ndarray of int, shape (n,)
            Row of ``sources`` for each measurement.
        """
        key = np.round(np.column_stack([self.theta_i, np.mod(self.phi_i, 360.0)]) / _INCIDENCE_TOLERANCE_DEG)
        # Normal incidence has no azimuth: treat every phi_i as the same source there.
        key[self.theta_i == 0.0, 1] = 0.0
        _, first, index = np.unique(key, axis=0, return_index=True, return_inverse=True)
        sources = np.column_stack([self.theta_i[first], self.phi_i[first]])
        return sources, np.asarray(index).reshape(-1)

    def subset(self, mask: Any) -> "Dataset":
        """A new dataset with the measurements selected by a boolean mask or index array."""
        select = np.asarray(mask)
        if select.dtype == bool:
            select = np.flatnonzero(select)
        return Dataset(
            *(getattr(self, name)[select] for name in (*_ANGLE_FIELDS, "value", "sigma")),
            quantity=self.quantity,
            label=self.label,
            metadata={k: ([v[i] for i in select] if k in PER_VALUE_METADATA else v) for k, v in self.metadata.items()},
            covariance=None if self.covariance is None else _covariance_subset(self.covariance, select),
        )

    # ------------------------------------------------------------------ persistence
    def to_dict(self, covariance: bool = True) -> dict[str, Any]:
        """Plain-Python form (lists), for JSON; ``covariance=False`` leaves the covariance
        out (a fit result writes it to a binary file of its own)."""
        out: dict[str, Any] = {name: getattr(self, name).tolist() for name in CSV_COLUMNS}
        out.update(quantity=self.quantity, label=self.label, metadata=dict(self.metadata))
        if covariance and self.covariance is not None:
            out["covariance"] = np.asarray(self.covariance).tolist()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Dataset":
        """Inverse of :meth:`to_dict`."""
        missing = [name for name in CSV_COLUMNS if name not in data]
        if missing:
            raise ValueError(f"dataset record lacks the field(s) {missing}; expected {list(CSV_COLUMNS)}")
        return cls(
            *(data[name] for name in CSV_COLUMNS),
            quantity=data.get("quantity", "brdf"),
            label=data.get("label", ""),
            metadata=data.get("metadata", {}),
            covariance=data.get("covariance"),
        )

    def to_csv(self, path: str | Path) -> Path:
        """Write the CSV form: ``# key: value`` header lines (values in JSON), then the
        columns ``theta_i,phi_i,theta_r,phi_r,value,sigma``.

        A covariance is written beside the file as ``<stem>_covariance.npy`` (numpy's
        format; ``<stem>_covariance.npz`` with the arrays ``independent`` and ``factors``
        for a :class:`~gonio.fitting.covariance.LowRankCovariance`), which the header line
        ``# covariance:`` names and :meth:`from_csv` reads back.
        """
        import json

        from gonio.files import json_default

        path = Path(path)
        header: dict[str, Any] = {"quantity": self.quantity}
        if self.label:
            header["label"] = self.label
        header.update(self.metadata)
        if self.covariance is not None:
            header["covariance"] = save_covariance(path.with_name(f"{path.stem}_covariance"), self.covariance).name
        buffer = io.StringIO()
        for key, value in header.items():
            buffer.write(f"# {key}: {json.dumps(value, default=json_default)}\n")
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(CSV_COLUMNS)
        for row in zip(*(getattr(self, name) for name in CSV_COLUMNS)):
            writer.writerow([repr(float(x)) for x in row])
        path.write_text(buffer.getvalue())
        return path

    @classmethod
    def from_csv(cls, path: str | Path, quantity: str | None = None, label: str | None = None,
                 columns: Mapping[str, str] | None = None, angle_unit: str | None = None) -> "Dataset":
        """Read a table of measurements: the columns ``theta_i,phi_i,theta_r,phi_r,value``
        and, optionally, ``sigma`` (:mod:`gonio.fitting.csv_table`; docs/data-format.md).

        Parameters
        ----------
        path : path
            The file.  Lines starting with ``#`` before the column names may hold ``key:
            value`` pairs (JSON values): ``quantity`` and ``label`` set those fields,
            ``covariance`` names a numpy ``.npy`` file beside it holding the values'
            covariance, ``angle_unit`` the angles' unit; others go to ``metadata``.
            Extra columns are ignored; comma, semicolon, tab or space delimited.
        quantity, label : str, optional
            Override the values given in the file.
        columns : mapping, optional
            gonio's column names to the file's, e.g. ``{"theta_i": "incidence"}``.
        angle_unit : {"deg", "rad"}, optional
            Unit of the angles (default: the header's ``angle_unit``, else degrees; angles
            that all lie within [0, pi/2] are refused as probable radians unless the unit
            is given).

        Without a ``sigma`` column every value's stated uncertainty is
        :data:`~gonio.fitting.csv_table.ASSUMED_RELATIVE_SIGMA` of itself and the
        metadata says so (:data:`~gonio.fitting.csv_table.ASSUMED_SIGMA`): a fit then
        takes the noise as relative and fits its size. Rows with a missing value are left
        out and counted in the metadata (:data:`~gonio.fitting.csv_table.DROPPED_ROWS`).

        Raises
        ------
        FileNotFoundError
            The file, or the covariance file its header names, does not exist.
        ValueError
            Naming the file, the line and the column that could not be read.
        """
        from .csv_table import ASSUMED_RELATIVE_SIGMA, ASSUMED_SIGMA, read_table

        path = Path(path)
        table = read_table(path, CSV_COLUMNS[:-1], ("sigma",), columns, angle_unit)
        header, data = dict(table.header), table.columns
        metadata = {**{k: v for k, v in header.items() if k not in ("quantity", "label", "covariance", "angle_unit")},
                    **table.metadata}
        if "sigma" not in data:
            magnitude = np.abs(data["value"])
            data["sigma"] = ASSUMED_RELATIVE_SIGMA * np.maximum(magnitude, 1e-3 * magnitude.max())
            metadata[ASSUMED_SIGMA] = (f"the file states no uncertainties: each value's taken as "
                                       f"{ASSUMED_RELATIVE_SIGMA:g} of itself, a fit's relative extra noise "
                                       "(rel_jitter) sets the real size")
        covariance = _covariance_beside(path, header.get("covariance"), table)
        try:
            return cls(*(data[c] for c in CSV_COLUMNS), quantity=quantity or str(header.get("quantity", "brdf")),
                       label=label if label is not None else str(header.get("label", path.stem)),
                       metadata=metadata, covariance=covariance)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None

    def __repr__(self) -> str:
        return f"<Dataset {self.label!r}: {self.n} {self.quantity} values>"


def save_covariance(stem: Path, covariance: Any) -> Path:
    """Write ``covariance`` as ``stem.npy`` (an (n, n) array) or ``stem.npz`` (a
    :class:`LowRankCovariance`: its ``independent`` and ``factors`` arrays); returns the path."""
    if isinstance(covariance, LowRankCovariance):
        path = stem.with_name(stem.name + ".npz")
        with open(path, "wb") as handle:
            np.savez(handle, **covariance.arrays())
        return path
    path = stem.with_name(stem.name + ".npy")
    np.save(path, np.asarray(covariance), allow_pickle=False)
    return path


def load_covariance(path: Path) -> Any:
    """The covariance :func:`save_covariance` wrote (``ValueError`` naming the file when it
    is neither form)."""
    try:
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as arrays:
                return LowRankCovariance(arrays["independent"], arrays["factors"])
        return np.load(path, allow_pickle=False)
    except (ValueError, KeyError, OSError) as error:
        raise ValueError(f"{path}: not a covariance file (an (n, n) .npy array, or a .npz with the arrays "
                         f"'independent' and 'factors'): {error}") from None


def _covariance_beside(path: Path, name: Any, table) -> Any:
    """The covariance a CSV's ``# covariance:`` line names (a ``.npy`` or ``.npz`` file
    beside it, :func:`save_covariance`), or None.

    Files of older versions say ``not stored (...)``: no covariance. Refused when rows were
    left out for a missing value (the matrix no longer matches the rows).
    """
    if not isinstance(name, str) or not name.endswith((".npy", ".npz")):
        return None
    covariance_path = path.parent / name
    if not covariance_path.is_file():
        raise FileNotFoundError(f"{path}: its header names the covariance file {name!r}, which is not beside it; copy "
                                "it along with the table, or delete the '# covariance:' line to take the errors as "
                                "independent")
    if table.metadata.get("dropped_rows"):
        raise ValueError(f"{path}: rows with a missing value were left out, so the covariance {name!r} no longer "
                         "matches the rows; remove those rows and their entries from both files")
    return load_covariance(covariance_path)


def _covariance_subset(covariance: Any, select: np.ndarray) -> Any:
    """The covariance of the values ``select`` (integer indices)."""
    if isinstance(covariance, LowRankCovariance):
        return covariance.subset(select)
    return covariance[np.ix_(select, select)]


def _checked_covariance(covariance: Any, sigma: np.ndarray) -> Any:
    """The covariance checked: (n, n), symmetric, diagonal sigma^2, positive definite; a
    :class:`LowRankCovariance` (positive definite by construction) for n values with the
    diagonal sigma^2, else a read-only float array."""
    if isinstance(covariance, LowRankCovariance):
        if covariance.n != sigma.size:
            raise ValueError(f"Dataset field 'covariance' covers {covariance.n} values; expected {sigma.size}")
        variance = covariance.variance()
        if not np.allclose(variance, sigma**2, rtol=1e-9, atol=0.0):
            k = int(np.argmax(np.abs(variance - sigma**2) / sigma**2))
            raise ValueError(f"Dataset field 'covariance': diagonal entry {k} = {variance[k]:g} is not "
                             f"sigma^2 = {sigma[k]**2:g}")
        return covariance
    matrix = np.array(covariance, dtype=float)
    n = sigma.size
    if matrix.shape != (n, n):
        raise ValueError(f"Dataset field 'covariance' has shape {matrix.shape}; expected ({n}, {n})")
    if not np.all(np.isfinite(matrix)):
        raise ValueError("Dataset field 'covariance' holds NaN or infinite entries")
    if not np.allclose(matrix, matrix.T, rtol=1e-10, atol=0.0):
        raise ValueError("Dataset field 'covariance' is not symmetric")
    if not np.allclose(np.diag(matrix), sigma**2, rtol=1e-9, atol=0.0):
        k = int(np.argmax(np.abs(np.diag(matrix) - sigma**2) / sigma**2))
        raise ValueError(f"Dataset field 'covariance': diagonal entry {k} = {matrix[k, k]:g} is not sigma^2 = {sigma[k]**2:g}")
    try:
        np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError:
        raise ValueError("Dataset field 'covariance' is not positive definite") from None
    matrix.setflags(write=False)
    return matrix

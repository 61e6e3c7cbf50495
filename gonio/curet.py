"""Reader for the CUReT BRDF measurements (abrdf.dat + table.txt).

The Columbia-Utrecht Reflectance and Texture database measured 61 real surfaces at the
same 205 combinations of illumination and viewing direction.  The two files read here
hold, per sample, the BRDF averaged over the red, green and blue channels
(``abrdf.dat``: one row per sample, the sample number then 205 values [1/sr]) and the
measurement geometry (``table.txt``: one row per measurement, its index then four angles
[rad]).

Angle order (an assumption, stated once and used everywhere): the columns of
``table.txt`` are read as (theta_v, phi_v, theta_i, phi_i) -- viewing polar angle and
azimuth, then illumination polar angle and azimuth -- which is how the code that
redistributes the files reads them.  The database itself only says the table gives the
illumination and viewing directions.  gonio's viewer is the "r" direction, so
``theta_r, phi_r = theta_v, phi_v``.  Pass ``angle_order="illumination-first"`` to read
the other way round; a reciprocal model (Koenderink-van Doorn series, Oren-Nayar, ...)
gives the same fit either way.

Checked properties of the geometry: the angle between the lamp and the camera directions
takes the seven values 22.5, 45, ..., 157.5 deg (multiples of 22.5 deg; zero, i.e. exact
retro-reflection, is absent because lamp and camera cannot share a direction), and all
polar angles lie below 84 deg.

Data quality: a few values are slightly negative (dark-subtraction noise; sample 61 has
most of them).  They are kept unchanged and flagged in :attr:`CuretSample.negative`;
nothing is clipped.  Shiny samples saturate near the specular direction; the files do not
mark those values.

References
----------
K. J. Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink, "Reflectance and texture of
real-world surfaces", ACM Transactions on Graphics 18(1), 1999 (credit them whenever the
data is used or shown).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "SAMPLE_NAMES",
    "ANGLE_ORDERS",
    "CuretSample",
    "CuretData",
    "read_curet",
    "read_curet_geometry",
    "read_curet_brdf",
]

#: Sample numbers named in the database's sample list (those gonio documents; the other
#: samples are called ``sample-NN``).
SAMPLE_NAMES: dict[int, str] = {
    6: "sandpaper",
    7: "velvet",
    10: "plaster_a",
    11: "plaster_b",
    30: "plaster_b zoomed",
}

#: Accepted readings of the column order of table.txt.
ANGLE_ORDERS = ("view-first", "illumination-first")

N_GEOMETRIES = 205


def sample_name(number: int) -> str:
    """Name of CUReT sample ``number`` (``sample-NN`` when gonio does not list it)."""
    return SAMPLE_NAMES.get(int(number), f"sample-{int(number):02d}")


@dataclass(frozen=True)
class CuretSample:
    """One CUReT sample: geometry [deg] and BRDF [1/sr] at its 205 measurements.

    Attributes
    ----------
    number : int
        Sample number, 1-61.
    name : str
        Name from :data:`SAMPLE_NAMES` or ``sample-NN``.
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        Illumination and viewing directions [deg] (angle order: module notes).
    brdf : numpy.ndarray
        BRDF [1/sr], RGB average, negative values kept.
    negative : numpy.ndarray of bool
        Where ``brdf < 0`` (noise after dark subtraction).
    """

    number: int
    name: str
    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    brdf: np.ndarray

    @property
    def negative(self) -> np.ndarray:
        """Mask of the negative (noise) values."""
        return self.brdf < 0.0


@dataclass(frozen=True)
class CuretData:
    """All samples of the two CUReT files.

    Attributes
    ----------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        The 205 measurement geometries [deg], shared by all samples.
    sample_numbers : numpy.ndarray of int
        Sample numbers in file order.
    brdf : numpy.ndarray
        BRDF [1/sr], shape (number of samples, 205).
    angle_order : str
        How the columns of table.txt were read (:data:`ANGLE_ORDERS`).
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    sample_numbers: np.ndarray
    brdf: np.ndarray
    angle_order: str

    @property
    def negative(self) -> np.ndarray:
        """Mask of negative BRDF values, shape like :attr:`brdf`."""
        return self.brdf < 0.0

    @property
    def names(self) -> list[str]:
        """Sample names in file order."""
        return [sample_name(n) for n in self.sample_numbers]

    def sample(self, key: int | str) -> CuretSample:
        """One sample by number (1-61) or name (e.g. ``"velvet"``).

        Raises
        ------
        ValueError
            If no sample has that number or name.
        """
        if isinstance(key, str):
            matches = [n for n in self.sample_numbers if sample_name(n) == key]
            if not matches:
                raise ValueError(f"no CUReT sample is named {key!r}; named samples: {sorted(set(self.names))}")
            number = int(matches[0])
        else:
            number = int(key)
        rows = np.flatnonzero(self.sample_numbers == number)
        if rows.size == 0:
            raise ValueError(
                f"CUReT sample number {key!r} is not in the data; valid numbers are "
                f"{int(self.sample_numbers.min())}-{int(self.sample_numbers.max())}"
            )
        return CuretSample(
            number, sample_name(number), self.theta_i, self.phi_i, self.theta_r, self.phi_r, self.brdf[rows[0]]
        )


def _numeric_rows(path: Path, columns: int, what: str) -> np.ndarray:
    try:
        text = path.read_text()
    except OSError as error:
        raise ValueError(f"{path}: cannot read the CUReT {what} file ({error.strerror})") from None
    rows = []
    for line_number, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != columns:
            raise ValueError(f"{path}, line {line_number}: expected {columns} numbers ({what}), found {len(fields)}")
        try:
            rows.append([float(x) for x in fields])
        except ValueError:
            raise ValueError(f"{path}, line {line_number}: expected {columns} numbers ({what}), got {line.strip()[:60]!r}") from None
    if not rows:
        raise ValueError(f"{path}: no data rows ({what})")
    return np.array(rows)


#: Environment variable naming the folder with abrdf.dat and table.txt.
ENVIRONMENT_VARIABLE = "GONIO_CURET_DIR"


def default_directory() -> Path:
    """The CUReT folder used when none is given.

    ``$GONIO_CURET_DIR`` if set, else ``shared/data/curet`` in the folder that holds the
    repository checkout (``<checkout>/../shared/data/curet``), where both a developer
    checkout and a fresh clone beside the project's shared data find it.  The path is
    returned whether or not it exists.
    """
    configured = os.environ.get(ENVIRONMENT_VARIABLE)
    if configured:
        return Path(configured)
    checkout = Path(__file__).resolve().parents[1]  # gonio/curet.py -> checkout
    return checkout.parent / "shared" / "data" / "curet"


def read_curet_geometry(path: str | Path, angle_order: str = "view-first") -> tuple[np.ndarray, ...]:
    """Measurement geometries of ``table.txt`` in degrees.

    Parameters
    ----------
    path : str or Path
        The table file: per row the index (1-205) and four angles [rad].
    angle_order : {"view-first", "illumination-first"}
        Column order of the angles (see the module notes).

    Returns
    -------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        Illumination and viewing directions [deg], in index order.

    Raises
    ------
    ValueError
        Naming the file, line and field when the table is malformed (wrong column count,
        indices not 1..N in order, non-finite angles, polar angles outside [0, 90] deg).
    """
    path = Path(path)
    if angle_order not in ANGLE_ORDERS:
        raise ValueError(f"angle_order = {angle_order!r} is not one of {list(ANGLE_ORDERS)}")
    table = _numeric_rows(path, 5, "index theta phi theta phi")
    index = table[:, 0]
    if not np.array_equal(index, np.arange(1, index.size + 1)):
        bad = int(np.flatnonzero(index != np.arange(1, index.size + 1))[0])
        raise ValueError(f"{path}, row {bad + 1}: measurement index {index[bad]:g}, expected {bad + 1}")
    degrees = np.degrees(table[:, 1:])
    if not np.all(np.isfinite(degrees)):
        raise ValueError(f"{path}: non-finite angle")
    first, second = (degrees[:, 0], degrees[:, 1]), (degrees[:, 2], degrees[:, 3])
    (theta_r, phi_r), (theta_i, phi_i) = (first, second) if angle_order == "view-first" else (second, first)
    for label, theta in (("theta_i", theta_i), ("theta_r", theta_r)):
        outside = (theta < 0.0) | (theta > 90.0)
        if np.any(outside):
            row = int(np.flatnonzero(outside)[0])
            raise ValueError(f"{path}, row {row + 1}: polar angle {label} = {theta[row]:g} deg is outside [0, 90] deg")
    return theta_i, phi_i, theta_r, phi_r


def read_curet_brdf(path: str | Path, n_geometries: int = N_GEOMETRIES) -> tuple[np.ndarray, np.ndarray]:
    """Sample numbers and BRDF rows of ``abrdf.dat``.

    Parameters
    ----------
    path : str or Path
        The BRDF file: per row the sample number and ``n_geometries`` values [1/sr].
    n_geometries : int
        Number of measurement geometries (rows of table.txt).

    Returns
    -------
    sample_numbers : numpy.ndarray of int
    brdf : numpy.ndarray
        Shape (samples, n_geometries) [1/sr]; negative values kept.

    Raises
    ------
    ValueError
        Naming the file and line for a wrong value count, a non-integer or repeated sample
        number, or a non-finite value.
    """
    path = Path(path)
    data = _numeric_rows(path, n_geometries + 1, f"sample number and {n_geometries} BRDF values")
    numbers = data[:, 0]
    if not np.all(numbers == np.round(numbers)) or len(set(numbers)) != numbers.size:
        raise ValueError(f"{path}: the first column must hold distinct integer sample numbers")
    brdf = data[:, 1:]
    if not np.all(np.isfinite(brdf)):
        row = int(np.flatnonzero(~np.isfinite(brdf).all(axis=1))[0])
        raise ValueError(f"{path}, line {row + 1}: non-finite BRDF value")
    return numbers.astype(int), brdf


def read_curet(directory: str | Path, angle_order: str = "view-first") -> CuretData:
    """Read ``abrdf.dat`` and ``table.txt`` from a directory.

    Parameters
    ----------
    directory : str or Path
        Folder holding the two files.
    angle_order : {"view-first", "illumination-first"}
        Column order of table.txt (module notes).

    Returns
    -------
    CuretData

    Examples
    --------
    >>> data = read_curet(default_directory())                  # doctest: +SKIP
    >>> velvet = data.sample("velvet")                           # doctest: +SKIP
    >>> velvet.brdf.shape, velvet.theta_i.shape                  # doctest: +SKIP
    ((205,), (205,))
    """
    directory = Path(directory)
    theta_i, phi_i, theta_r, phi_r = read_curet_geometry(directory / "table.txt", angle_order)
    numbers, brdf = read_curet_brdf(directory / "abrdf.dat", n_geometries=theta_i.size)
    return CuretData(theta_i, phi_i, theta_r, phi_r, numbers, brdf, angle_order)

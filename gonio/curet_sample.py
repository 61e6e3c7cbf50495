"""A measured CUReT material as a BRDF over the whole hemisphere (an emulated sample).

CUReT (Dana, van Ginneken, Nayar & Koenderink 1999) measured each of its 61 samples at the
same 205 pairs of illumination and viewing directions.  To put such a material on the
emulated rig, gonio needs its BRDF at *every* pair of directions, so the 205 values are
interpolated by the isotropic, reciprocal Koenderink-van Doorn series (KvD 1998, eq 26-31;
:mod:`gonio.models.kvd`), which Koenderink, van Doorn, Dana & Nayar (1999) proposed for
summarising exactly these data:

* **Fit.** The series of radial order N is fitted by Tikhonov-regularised least squares
  (:func:`gonio.models.kvd.fit_series`, weight :data:`REGULARIZATION` = 1e-5 sr^-2, the
  weight of gonio's CUReT noise model, which keeps the high orders from ringing between
  the geometries).  Every term is symmetric in source and viewer and depends on the
  azimuths only through their difference, so the interpolant is exactly reciprocal and
  isotropic whatever the data.
* **Order.** N is chosen per sample among :data:`ORDERS` (0-10; order 10 has 91
  amplitudes, fewer than half the 205 values) by exact leave-one-out cross-validation
  with the one-standard-error rule (:func:`gonio.models.kvd.select_order`): the lowest
  order whose leave-one-out mean square error is within one standard error of the
  smallest.  It is deterministic (no random folds).  The curves and the chosen orders of
  all 61 samples are in docs/curet-samples.md (``python -m gonio.curet_sample``).
* **Non-negativity.** A truncated series can dip below zero, mostly near grazing
  directions outside the measured range (polar angles above 84 deg) and on dark samples.
  A BRDF cannot be negative, so the sample returns ``max(series, 0)``: zero where the
  series is negative, the series elsewhere (reciprocity is kept, NaN stays NaN).
  :meth:`CuretBrdf.series` gives the unclipped series.

References
----------
K. J. Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink, "Reflectance and texture of
real-world surfaces", ACM Transactions on Graphics 18(1), 1999 (the data; credit them).
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-31 (the series).  J. J. Koenderink, A. J. van
Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection distribution function expressed
in terms of surface scattering modes", ECCV 1996 / 1999 (the series fitted to CUReT).
T. Hastie, R. Tibshirani, J. Friedman, "The Elements of Statistical Learning", 2nd ed.,
2009, section 7.10 (cross-validation, one-standard-error rule).
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np
from numpy.typing import ArrayLike

from gonio.curet import SAMPLE_NAMES, CuretData, CuretSample, default_directory, read_curet, sample_name

if TYPE_CHECKING:
    from gonio.models.kvd import OrderSelection, SeriesFit

__all__ = [
    "ORDERS",
    "REGULARIZATION",
    "RULE",
    "CuretBrdf",
    "interpolate",
    "resolve_sample",
    "curet_brdf",
    "order_table",
]

#: Candidate radial orders of the series.
ORDERS = tuple(range(0, 11))
#: Tikhonov weight of every fit [sr^-2] (as gonio's CUReT noise model).
REGULARIZATION = 1e-5
#: Cross-validation rule (:data:`gonio.models.kvd.SELECTION_RULES`).
RULE = "one-standard-error"


@dataclass(frozen=True)
class CuretBrdf:
    """A CUReT sample interpolated by a KvD series: a BRDF callable [1/sr].

    Call it as ``brdf(theta_i, phi_i, theta_r, phi_r)`` with angles in degrees
    (broadcasting): it returns ``max(series, 0)``, 0 below the horizon, NaN for NaN
    angles.  Exactly reciprocal and isotropic.

    Attributes
    ----------
    number : int
        CUReT sample number (1-61).
    name : str
        Sample name (:func:`gonio.curet.sample_name`).
    fit : gonio.models.kvd.SeriesFit
        The series fitted to the 205 values at the chosen order.
    selection : gonio.models.kvd.OrderSelection
        The cross-validation curve and the chosen order.
    """

    number: int
    name: str
    fit: "SeriesFit"
    selection: "OrderSelection"

    @property
    def order(self) -> int:
        """Radial order of the series [-]."""
        return int(self.selection.chosen)

    @property
    def coefficients(self):
        """The series amplitudes (:class:`gonio.models.kvd.KvdCoefficients`)."""
        return self.fit.coefficients

    @functools.cached_property
    def _model(self):
        return self.fit.coefficients.model(name=f"curet-{self.number}")

    def series(self, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike) -> np.ndarray:
        """The fitted series itself [1/sr], unclipped (may be negative)."""
        return np.asarray(self._model(theta_i, phi_i, theta_r, phi_r), dtype=float)

    def __call__(self, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike) -> np.ndarray:
        """BRDF [1/sr] at angles in degrees: ``max(series, 0)`` (module notes)."""
        return np.maximum(self.series(theta_i, phi_i, theta_r, phi_r), 0.0)

    def describe(self) -> str:
        """One line for logs and metadata."""
        return (f"CUReT {self.number} {self.name}: KvD series of order {self.order} "
                f"({len(self.coefficients.modes)} amplitudes), leave-one-out rms "
                f"{self.selection.curve()[self.order]:.4f} relative, floored at 0")


def interpolate(
    sample: CuretSample,
    orders: tuple[int, ...] = ORDERS,
    regularization: float = REGULARIZATION,
    rule: str = RULE,
) -> CuretBrdf:
    """Interpolate one CUReT sample by the KvD series of the cross-validated order.

    Parameters
    ----------
    sample : gonio.curet.CuretSample
        Geometries [deg] and BRDF [1/sr] of the 205 measurements (negative noise values
        used as they are).
    orders : tuple of int
        Candidate radial orders [-].
    regularization : float
        Tikhonov weight [sr^-2].
    rule : {"one-standard-error", "minimum"}
        Cross-validation rule (:func:`gonio.models.kvd.select_order`).

    Returns
    -------
    CuretBrdf

    Notes
    -----
    The order minimises (or nearly minimises, by the rule) the leave-one-out error
    ``sqrt(mean(e^2) / mean(f^2))``; the series of that order is then fitted to all 205
    values (KvD 1998, eq 26-31).

    Examples
    --------
    >>> from gonio.curet import read_curet, default_directory        # doctest: +SKIP
    >>> plaster = interpolate(read_curet(default_directory()).sample(10))  # doctest: +SKIP
    >>> plaster.order                                                 # doctest: +SKIP
    4
    """
    from gonio.models import kvd

    geometry = (sample.theta_i, sample.phi_i, sample.theta_r, sample.phi_r)
    selection = kvd.select_order(*geometry, sample.brdf, orders=orders, regularization=regularization, rule=rule)
    fit = kvd.fit_series(*geometry, sample.brdf, order=selection.chosen, regularization=regularization)
    return CuretBrdf(sample.number, sample.name, fit, selection)


def _normalised(name: str) -> str:
    return re.sub(r"[\s\-]+", "_", name.strip().lower())


def resolve_sample(key: int | str, data: CuretData) -> int:
    """The sample number a user's key names: a number (``"10"``) or a name (``"plaster_a"``).

    Names match case-insensitively with spaces, hyphens and underscores alike
    (``plaster_b-zoomed`` is sample 30; ``sample-12`` is 12).

    Raises
    ------
    ValueError
        Naming the key and what is expected: a number in the data's range, or one of the
        known names.
    """
    numbers = [int(n) for n in data.sample_numbers]
    valid = f"a sample number {min(numbers)}-{max(numbers)} or a name ({', '.join(sorted(SAMPLE_NAMES.values()))}, sample-NN)"
    text = str(key).strip()
    if re.fullmatch(r"[+-]?\d+", text):
        number = int(text)
        if number not in numbers:
            raise ValueError(f"CUReT sample number {number} is not in the data; expected {valid}")
        return number
    by_name = {_normalised(sample_name(n)): n for n in numbers}
    if _normalised(text) in by_name:
        return by_name[_normalised(text)]
    raise ValueError(f"{text!r} is not a CUReT sample; expected {valid}")


@functools.lru_cache(maxsize=8)
def _cached(directory: str, number: int) -> CuretBrdf:
    return interpolate(read_curet(directory).sample(number))


def curet_brdf(key: int | str, directory: str | Path | None = None) -> CuretBrdf:
    """The interpolated BRDF of CUReT sample ``key`` (number or name).

    Parameters
    ----------
    key : int or str
        Sample number (1-61) or name (:func:`resolve_sample`).
    directory : str or Path, optional
        Folder with ``abrdf.dat`` and ``table.txt``; default
        :func:`gonio.curet.default_directory` (``$GONIO_CURET_DIR``).

    Returns
    -------
    CuretBrdf
        Cached per folder and sample (the fit is deterministic).

    Raises
    ------
    ValueError
        Unknown sample, or unreadable files (naming the file).
    """
    folder = Path(directory) if directory is not None else default_directory()
    data = read_curet(folder)
    return _cached(str(folder), resolve_sample(key, data))


def order_table(data: CuretData, rule: str = RULE, numbers: Iterable[int] | None = None) -> str:
    """Markdown table of the cross-validation curve and chosen order of every sample.

    Parameters
    ----------
    data : gonio.curet.CuretData
    rule : str
        Cross-validation rule.
    numbers : iterable of int, optional
        The samples to list (default all, in file order).

    Returns
    -------
    str
        One row per sample: number, name, chosen order, amplitudes, relative leave-one-out
        error at each order of :data:`ORDERS` (the chosen one in bold, the minimum marked *).
    """
    header = "| sample | name | order | amplitudes | " + " | ".join(f"N={o}" for o in ORDERS) + " |"
    lines = [header, "|" + "---|" * (4 + len(ORDERS))]
    for number in data.sample_numbers if numbers is None else numbers:
        brdf = interpolate(data.sample(int(number)), rule=rule)
        sel = brdf.selection
        cells = []
        for order, value in zip(sel.orders, sel.cv_rms):
            text = f"{value:.4f}" + ("*" if order == sel.best else "")
            cells.append(f"**{text}**" if order == sel.chosen else text)
        lines.append(f"| {brdf.number} | {brdf.name} | {sel.chosen} | {len(brdf.coefficients.modes)} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(order_table(read_curet(default_directory())), end="")

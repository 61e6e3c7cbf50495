"""Coefficient sets of the isotropic KvD series and their evaluation as a BRDF.

A :class:`KvdCoefficients` holds the amplitudes a_nml of the modes I_nml up to some order
(KvD eq 28): the BRDF is the truncated sum ``f = sum a_nml I_nml``.  Coefficients are
dimensionless because I_nml carries the unit 1/sr.  Every term is symmetric in source and
viewer, so any coefficient set is exactly reciprocal.  A truncated series need not be
non-negative: gonio returns it as it is (no clipping), so ringing stays visible.

Truncating a series abruptly rings (KvD Fig 4 caption), as a truncated Fourier series
does; :meth:`KvdCoefficients.damped` attenuates the high orders gradually instead.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-29 and Figs 3-6.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from gonio.models._core import LinearForm, Model, Param, with_linear_form
from gonio.zernike import _check_order

from .basis import Mode, check_isotropic_index, design_matrix, isotropic_indices

__all__ = ["KvdCoefficients", "DAMPING_WINDOWS", "damping_window", "coefficient_name", "series_model"]

#: Names of the damping windows understood by :func:`damping_window`.
DAMPING_WINDOWS = ("none", "fejer", "lanczos")

REFERENCE = (
    "Koenderink & van Doorn, JOSA A 15(11) 1998: isotropic reciprocal basis I_nml eq 26-27, "
    "series eq 28, index rules eq 30-31, Figs 3-6"
)


def coefficient_name(n: int, m: int, l: int) -> str:
    """Parameter name of the amplitude of mode (n, m, l), e.g. ``a_2_2_0``."""
    return f"a_{n}_{m}_{l}"


def damping_window(n: ArrayLike, order: int, window: str = "none") -> np.ndarray:
    """Attenuation factor of radial order n in a series truncated at ``order`` [-].

    Parameters
    ----------
    n : array_like of int
        Radial orders [-], ``0 <= n <= order``.
    order : int
        Truncation order N [-].
    window : {"none", "fejer", "lanczos"}
        ``"none"``: 1 (abrupt truncation); ``"fejer"``: ``1 - n/(N+1)`` (Cesaro mean of
        the partial sums); ``"lanczos"``: ``sinc(n/(N+1))``.

    Returns
    -------
    numpy.ndarray
        Factors in (0, 1], equal to 1 at n = 0 so the Lambertian mode is untouched.

    Notes
    -----
    KvD (Fig 4 caption) note that the ringing of an abruptly truncated series can be damped
    by attenuating the amplitudes gradually, as for Fourier series; they do not specify a
    window.  gonio offers the two classical Fourier windows above, applied per hemisphere
    factor: mode (n, m, l) is multiplied by ``w(n) w(m)``, the window of the product basis
    K_n(i) K_m(r) of eq 20.

    Examples
    --------
    >>> damping_window([0, 2, 4], 4, "fejer").round(12).tolist()
    [1.0, 0.6, 0.2]
    """
    order = _check_order(order)
    if window not in DAMPING_WINDOWS:
        raise ValueError(f"damping window {window!r} is not one of {list(DAMPING_WINDOWS)}")
    x = np.asarray(n, dtype=float) / (order + 1.0)
    if window == "fejer":
        return 1.0 - x
    if window == "lanczos":
        return np.sinc(x)
    return np.ones_like(x)


@dataclass(frozen=True)
class KvdCoefficients:
    """Amplitudes of the isotropic KvD modes (KvD eq 28).

    Parameters
    ----------
    modes : tuple of (n, m, l)
        The modes, each obeying the index rules of eq 30-31.
    values : numpy.ndarray
        Their amplitudes a_nml [-] (same length), finite.

    Examples
    --------
    >>> lambert = KvdCoefficients.from_mapping({(0, 0, 0): 2 * 0.5})   # rho = 0.5
    >>> round(float(lambert(30.0, 0.0, 60.0, 90.0)) * np.pi, 12)
    0.5
    """

    modes: tuple[Mode, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        modes = tuple(check_isotropic_index(*mode) for mode in self.modes)
        if len(set(modes)) != len(modes):
            twice = next(mode for mode in modes if modes.count(mode) > 1)
            raise ValueError(f"KvdCoefficients: the mode (n, m, l) = {twice} appears twice")
        values = np.array(self.values, dtype=float).reshape(-1)
        if values.shape != (len(modes),):
            raise ValueError(f"KvdCoefficients: {len(modes)} modes but {values.size} values")
        if not np.all(np.isfinite(values)):
            bad = int(np.flatnonzero(~np.isfinite(values))[0])
            raise ValueError(
                f"KvdCoefficients: coefficient values must be finite, got {values[bad]} for mode {modes[bad]}"
            )
        values.setflags(write=False)
        object.__setattr__(self, "modes", modes)
        object.__setattr__(self, "values", values)

    # ------------------------------------------------------------------ construction
    @classmethod
    def zeros(cls, order: int) -> "KvdCoefficients":
        """All modes up to ``order`` with zero amplitude (``ValueError`` if order < 0)."""
        modes = isotropic_indices(order)
        return cls(tuple(modes), np.zeros(len(modes)))

    @classmethod
    def from_mapping(cls, amplitudes: Mapping[Mode, float]) -> "KvdCoefficients":
        """Build from ``{(n, m, l): a_nml}``."""
        modes = tuple(sorted(tuple(int(v) for v in mode) for mode in amplitudes))
        return cls(modes, np.array([amplitudes[mode] for mode in modes], dtype=float))

    # ------------------------------------------------------------------ views
    @property
    def order(self) -> int:
        """Highest radial order present (0 for an empty set)."""
        return max((n for n, _, _ in self.modes), default=0)

    def as_dict(self) -> dict[Mode, float]:
        """``{(n, m, l): a_nml}``."""
        return {mode: float(v) for mode, v in zip(self.modes, self.values)}

    def __getitem__(self, mode: Mode) -> float:
        """Amplitude of ``mode`` (0 if the mode is absent)."""
        return self.as_dict().get(check_isotropic_index(*mode), 0.0)

    def __add__(self, other: "KvdCoefficients") -> "KvdCoefficients":
        if not isinstance(other, KvdCoefficients):
            return NotImplemented
        total = self.as_dict()
        for mode, value in other.as_dict().items():
            total[mode] = total.get(mode, 0.0) + value
        return KvdCoefficients.from_mapping(total)

    def __mul__(self, factor: float) -> "KvdCoefficients":
        return KvdCoefficients(self.modes, self.values * float(factor))

    __rmul__ = __mul__

    def truncated(self, order: int) -> "KvdCoefficients":
        """The modes with n <= ``order`` (``ValueError`` if order < 0)."""
        order = _check_order(order)
        keep = [j for j, (n, _, _) in enumerate(self.modes) if n <= order]
        return KvdCoefficients(tuple(self.modes[j] for j in keep), self.values[keep])

    def damped(self, window: str = "fejer", order: int | None = None) -> "KvdCoefficients":
        """Amplitudes multiplied by ``w(n) w(m)`` of :func:`damping_window`.

        Parameters
        ----------
        window : {"none", "fejer", "lanczos"}
            Damping window.
        order : int, optional
            Truncation order N of the window; defaults to :attr:`order`.
        """
        order = self.order if order is None else _check_order(order)
        kept = self.truncated(order)
        n = np.array([mode[0] for mode in kept.modes])
        m = np.array([mode[1] for mode in kept.modes])
        factor = damping_window(n, order, window) * damping_window(m, order, window)
        return KvdCoefficients(kept.modes, kept.values * factor)

    # ------------------------------------------------------------------ evaluation
    def model(self, name: str = "kvd-series") -> Model:
        """This series as an (unregistered) gonio :class:`~gonio.models.Model`."""
        return series_model(self, name=name)

    def __call__(self, theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike) -> np.ndarray:
        """Series value [1/sr] at angles in degrees (horizon and NaN rules of gonio models)."""
        return self.model()(theta_i, phi_i, theta_r, phi_r)


def _prepare_for(modes: Sequence[Mode]):
    names = [coefficient_name(*mode) for mode in modes]

    def prepare(theta_i, phi_i, theta_r, phi_r):
        shape = np.broadcast_shapes(*(np.shape(a) for a in (theta_i, phi_i, theta_r, phi_r)))
        ti, pi_, tr, pr = (np.broadcast_to(np.asarray(a, float), shape).ravel() for a in (theta_i, phi_i, theta_r, phi_r))
        matrix = design_matrix(modes, np.cos(ti), np.cos(tr), pr - pi_)

        def evaluate(**params: float | np.ndarray) -> np.ndarray:
            amplitudes = [params[name] for name in names]
            if not any(np.ndim(a) for a in amplitudes):
                return (matrix @ np.array(amplitudes)).reshape(shape)
            # amplitude arrays run along the flat geometry (last axis, length 1 or n)
            out = sum(np.multiply(a, matrix[:, j]) for j, a in enumerate(amplitudes))
            return out.reshape(out.shape[:-1] + shape)

        def amplitudes_of(**params: float | np.ndarray) -> tuple:
            return tuple(params[name] for name in names)

        if shape == (matrix.shape[0],):  # flat geometry (the fixed-geometry path): linear in the amplitudes
            return with_linear_form(evaluate, lambda: LinearForm(matrix.T.copy(), amplitudes_of))
        return evaluate

    return prepare


def series_params(coefficients: KvdCoefficients) -> tuple[Param, ...]:
    """Parameter specs of a series: one dimensionless amplitude per mode.

    Bounds: the lowest amplitude is ``a_000 = (1/(2 pi)) integral f dOmega_i dOmega_r`` and
    so cannot be negative for a non-negative BRDF; the other amplitudes have no physical
    bound (a narrow specular lobe has arbitrarily large high-order amplitudes).
    """
    params = []
    for (n, m, l), value in zip(coefficients.modes, coefficients.values):
        lowest = (n, m, l) == (0, 0, 0)
        params.append(
            Param(
                coefficient_name(n, m, l),
                "-",
                float(value),
                (0.0 if lowest else -math.inf, math.inf),
                f"amplitude of the KvD isotropic mode I_{n}{m}{l} (eq 26)"
                + ("; 2 x albedo for a Lambertian surface" if lowest else ""),
            )
        )
    return tuple(params)


def series_model(coefficients: KvdCoefficients, name: str = "kvd-series", description: str | None = None) -> Model:
    """A gonio model evaluating a truncated KvD series.

    Parameters
    ----------
    coefficients : KvdCoefficients
        Modes and amplitudes; the amplitudes become the parameter defaults, so
        ``model(ti, pi, tr, pr)`` evaluates this series and keyword arguments
        ``a_n_m_l=...`` override single amplitudes (fitting uses this).
    name : str
        Model name (the model is not registered).
    description : str, optional
        One line for listings.

    Returns
    -------
    Model
        Reciprocal and isotropic by construction; linear in every amplitude; not claimed
        to conserve energy.  The BRDF is ``sum a_nml I_nml`` (KvD eq 28), 0 below the
        horizon, NaN for NaN angles; not clipped at zero.

    Raises
    ------
    ValueError
        If the amplitude of the lowest mode is negative.

    Examples
    --------
    >>> lambert = series_model(KvdCoefficients.from_mapping({(0, 0, 0): 1.6}))
    >>> round(float(lambert(0.0, 0.0, 45.0, 0.0)) * np.pi, 12)
    0.8
    """
    if coefficients[(0, 0, 0)] < 0.0:
        raise ValueError(
            f"a_0_0_0 = {coefficients[(0, 0, 0)]:g} is negative; the lowest amplitude of a "
            "non-negative BRDF lies in [0, inf)"
        )
    if (0, 0, 0) not in coefficients.modes:
        coefficients = coefficients + KvdCoefficients(((0, 0, 0),), np.zeros(1))
    params = series_params(coefficients)
    return Model(
        name=name,
        params=params,
        reference=REFERENCE,
        description=description or f"KvD isotropic series of order {coefficients.order} ({len(params)} modes)",
        prepare=_prepare_for(coefficients.modes),
        energy_conserving=False,
        reciprocal=True,
        isotropic=True,
        linear_in=tuple(p.name for p in params),
        broadcasts_params=True,
        compiled=_compiled_series(coefficients.modes),
    )


def _compiled_series(modes: Sequence[Mode]):
    """Loader of the compiled plain call of a series (numba loads on first use)."""
    names = [coefficient_name(*mode) for mode in modes]

    def load():
        from .compiled import series_plain

        return series_plain(modes, names)

    return load

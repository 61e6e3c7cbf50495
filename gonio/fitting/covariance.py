"""Covariances of measurement errors, and the noise they give a likelihood.

A reduced recording's errors are independent per value except for a few sources that
every value, or every value of a group, shares: the sample's texture, its mountings, the
PRNU of nested camera windows, the linearity correction's coefficients, the reference
standard's calibration (gonio.reduction). Their covariance is therefore a diagonal plus a
matrix of low rank,

    C = D + U U^T,   D = diag(d) (d > 0, the independent part),   U of shape (n, k),

with k the number of shared sources, small against the number of values n.
:class:`LowRankCovariance` holds ``d`` and ``U`` and never forms the n x n matrix; a fit
whitens, takes log-determinants, draws noise and forms leave-one-out conditionals in
O(n k^2) time and O(n k) memory through the Woodbury identity (Rasmussen & Williams 2006,
Gaussian Processes for Machine Learning, eq A.9-A.10):

    C^-1 = D^-1/2 (I - V (I + G)^-1 V^T) D^-1/2,   det C = det D det(I + G),

with ``V = D^-1/2 U`` and ``G = V^T V`` (k x k). The whitening used is the symmetric one,
``W = (I + V V^T)^-1/2 D^-1/2 = (I - V M V^T) D^-1/2`` with ``M = R diag(1 / (t (t + 1))) R^T``,
``G = R diag(s^2) R^T`` and ``t = sqrt(1 + s^2)``: then ``W C W^T = I`` and ``|W r|^2 =
r^T C^-1 r``, and ``1 / (t (t + 1))`` stays finite (1/2) where a shared source has no
weight (s = 0).

The noise classes give :class:`gonio.fitting.FitProblem` one interface for independent
errors (:class:`DiagonalNoise`), a dense covariance (:class:`DenseNoise`, Cholesky) and a
structured one (:class:`LowRankNoise`).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["LowRankCovariance", "DiagonalNoise", "DenseNoise", "LowRankNoise", "noise_of"]

#: Most values (rows x n x k) a temporary of :class:`LowRankNoise`'s per-row factorisations
#: holds: 32 MB of doubles.
CHUNK_ELEMENTS = 2**22


class LowRankCovariance:
    """A covariance ``diag(d) + U U^T`` kept as its two parts [unit^2].

    Parameters
    ----------
    independent : array_like, shape (n,)
        ``d``: the variance of each value's independent errors (> 0).
    factors : array_like, shape (n, k)
        ``U``: one column per shared error source, each value's error from it (k may be 0).

    ``numpy.asarray`` of it gives the dense (n, n) matrix, for callers that need one (at a
    cost of n^2 memory); the fit does not.

    Examples
    --------
    >>> c = LowRankCovariance([1.0, 4.0], [[1.0], [2.0]])
    >>> np.asarray(c).tolist()
    [[2.0, 2.0], [2.0, 8.0]]
    >>> c.variance().tolist()
    [2.0, 8.0]
    """

    def __init__(self, independent: Any, factors: Any) -> None:
        d = np.asarray(independent, float).reshape(-1)
        u = np.asarray(factors, float)
        if u.ndim < 2:
            u = u.reshape(-1, 1) if u.size else np.zeros((d.size, 0))
        if u.ndim != 2 or u.shape[0] != d.size:
            raise ValueError(f"covariance factors of shape {u.shape} have {u.shape[0]} rows for {d.size} values; "
                             "expected one row per value and one column per shared source")
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(u))):
            raise ValueError("covariance: the independent variances or the shared factors hold NaN or infinite entries")
        if np.any(d <= 0.0):
            k = int(np.flatnonzero(d <= 0.0)[0])
            raise ValueError(f"covariance: value {k}'s independent variance is {d[k]:g}; it must be > 0 (every "
                             "measured value has some noise of its own: shot and read noise)")
        self.independent, self.factors = d, u
        for array in (self.independent, self.factors):
            array.setflags(write=False)

    @property
    def n(self) -> int:
        """Number of values."""
        return int(self.independent.size)

    @property
    def rank(self) -> int:
        """Number of shared error sources (columns of the factors)."""
        return int(self.factors.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        """(n, n), as the dense matrix's."""
        return (self.n, self.n)

    def variance(self) -> np.ndarray:
        """The diagonal of the covariance: each value's total variance, shape (n,)."""
        return self.independent + np.einsum("nk,nk->n", self.factors, self.factors)

    def dense(self) -> np.ndarray:
        """The (n, n) matrix ``diag(d) + U U^T``."""
        out = self.factors @ self.factors.T
        out.flat[:: self.n + 1] += self.independent
        return out

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        matrix = self.dense()
        return matrix if dtype is None else matrix.astype(dtype)

    def __getitem__(self, key: Any) -> np.ndarray:
        """Entries of the dense matrix: ``c[i, j]`` from the two parts (O(k)), any other
        index (``c[:3, :3]``) of the dense matrix formed for the call."""
        if isinstance(key, tuple) and len(key) == 2 and all(isinstance(k, (int, np.integer)) for k in key):
            i, j = (int(k) + self.n if k < 0 else int(k) for k in key)
            return np.float64(self.factors[i] @ self.factors[j] + (self.independent[i] if i == j else 0.0))
        return self.dense()[key]

    def subset(self, index: np.ndarray) -> "LowRankCovariance":
        """The covariance of the values ``index`` (integer indices)."""
        return LowRankCovariance(self.independent[index], self.factors[index])

    def scaled(self, scale: Any) -> "LowRankCovariance":
        """``diag(s) C diag(s)``: the covariance of the values multiplied by ``scale`` (n,)."""
        s = np.broadcast_to(np.asarray(scale, float), (self.n,))
        return LowRankCovariance(self.independent * s**2, self.factors * s[:, None])

    def with_factors(self, columns: Any) -> "LowRankCovariance":
        """This covariance plus ``V V^T`` for more shared sources ``columns`` (n, m)."""
        v = np.asarray(columns, float).reshape(self.n, -1)
        return LowRankCovariance(self.independent, np.hstack([self.factors, v]))

    def arrays(self) -> dict[str, np.ndarray]:
        """The parts by name, for ``numpy.savez``: ``independent`` and ``factors``."""
        return {"independent": np.asarray(self.independent), "factors": np.asarray(self.factors)}

    def __repr__(self) -> str:
        return f"<LowRankCovariance: {self.n} values, {self.rank} shared sources>"


def block_diagonal(parts: list[Any]) -> Any:
    """The covariance of several datasets' values, independent between datasets: a
    :class:`LowRankCovariance` when every part is one (each part's factors in their own
    columns), else the dense block-diagonal matrix. ``parts`` are (n_i, n_i) arrays or
    :class:`LowRankCovariance`."""
    if all(isinstance(p, LowRankCovariance) for p in parts):
        n = sum(p.n for p in parts)
        factors = np.zeros((n, sum(p.rank for p in parts)))
        row = column = 0
        for p in parts:
            factors[row:row + p.n, column:column + p.rank] = p.factors
            row, column = row + p.n, column + p.rank
        return LowRankCovariance(np.concatenate([p.independent for p in parts]), factors)
    matrices = [np.asarray(p, float) for p in parts]
    out = np.zeros((sum(len(m) for m in matrices),) * 2)
    start = 0
    for m in matrices:
        out[start:start + len(m), start:start + len(m)] = m
        start += len(m)
    return out


# ---------------------------------------------------------------------- the likelihood's noise
class DiagonalNoise:
    """Independent errors of standard deviation ``sigma`` (n,)."""

    correlated = False

    def __init__(self, sigma: np.ndarray) -> None:
        self.sigma = np.asarray(sigma, float)
        self.half_log_det = float(np.sum(np.log(self.sigma)))

    def whiten(self, difference: np.ndarray, extra: np.ndarray | float = 0.0) -> tuple[np.ndarray, float]:
        """``difference / sigma_tot`` ((n,) or (n, K)) and ``sum log sigma_tot``."""
        if np.all(np.asarray(extra) == 0.0):
            sigma = self.sigma
        else:
            sigma = np.sqrt(self.sigma**2 + extra)
        scale = sigma if np.ndim(difference) == 1 else sigma[:, None]
        return difference / scale, float(np.sum(np.log(sigma)))

    def whiten_rows(self, rows: np.ndarray) -> np.ndarray:
        """:meth:`whiten` of every row of ``rows`` (W, n), without extra noise."""
        return rows / self.sigma

    def chi_square_rows(self, rows: np.ndarray, extra: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """``r^T C_w^-1 r`` and ``1/2 log det C_w`` of every residual row ``r`` (W, n), with
        ``C_w`` the covariance plus the extra variance of row w (``extra``: (W, n), (n,)
        or a float) on its diagonal."""
        variance = np.broadcast_to(self.sigma**2 + np.asarray(extra), rows.shape)
        return np.sum(rows**2 / variance, axis=-1), 0.5 * np.sum(np.log(variance), axis=-1)

    def draw(self, rng: np.random.Generator, rows: int) -> np.ndarray:
        """``rows`` draws of the errors, shape (rows, n)."""
        return rng.standard_normal((rows, self.sigma.size)) * self.sigma

    def loo(self, rows: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
        """Log density of each value given the others, for residual rows (W, n)."""
        variance = self.sigma**2 + extra
        return -0.5 * rows**2 / variance - 0.5 * np.log(variance) - 0.5 * math.log(2.0 * math.pi)


def _lapack():
    """LAPACK's Cholesky factorisation and triangular solve (``dpotrf``, ``dtrtrs``),
    imported on first use: called directly they cost a third of scipy.linalg's wrappers,
    which check their inputs on every call."""
    from scipy.linalg.lapack import dpotrf, dtrtrs

    return dpotrf, dtrtrs


class DenseNoise:
    """Errors of a dense covariance ``C`` (n, n), whitened by its Cholesky factor ``L``."""

    correlated = True

    def __init__(self, covariance: np.ndarray) -> None:
        self.covariance = np.asarray(covariance, float)
        self.cholesky = np.linalg.cholesky(self.covariance)
        self.half_log_det = float(np.sum(np.log(np.diag(self.cholesky))))
        self._whitener: np.ndarray | None = None
        self._precision: np.ndarray | None = None

    def whiten(self, difference: np.ndarray, extra: np.ndarray | float = 0.0) -> tuple[np.ndarray, float]:
        """``L^-1 difference`` ((n,) or (n, K)), ``L`` the Cholesky factor of ``C`` plus the
        extra variance on its diagonal, and ``log det L``."""
        potrf, trtrs = _lapack()
        if np.all(np.asarray(extra) == 0.0):
            factor = self.cholesky
        else:  # LAPACK directly: a fit with a free extra noise factors once per walker and step
            matrix = self.covariance.copy()
            matrix.flat[:: len(matrix) + 1] += extra
            factor, info = potrf(matrix, lower=1, clean=1, overwrite_a=1)
            if info != 0:
                factor = np.linalg.cholesky(matrix)  # raises LinAlgError, naming the problem
        z, _ = trtrs(factor, difference, lower=1)
        return z, float(np.sum(np.log(np.diag(factor))))

    def whitening_matrix(self) -> np.ndarray:
        """``L^-1`` (computed once).

        One matrix product per batch instead of a triangular solve: LAPACK's solve of a few
        dozen right-hand sides is threaded and took 10 ms on a loaded 2-core machine (the
        product 0.01 ms); the same whitened residuals to rounding. An explicit inverse loses
        about cond(L) times the rounding of a solve: harmless for the reduction's
        covariances (a diagonal dominated by each value's own noise).
        """
        if self._whitener is None:
            from scipy.linalg import solve_triangular

            self._whitener = solve_triangular(self.cholesky, np.eye(len(self.cholesky)), lower=True)
        return self._whitener

    def whiten_rows(self, rows: np.ndarray) -> np.ndarray:
        """``L^-1`` applied to every row of ``rows`` (W, n)."""
        return rows @ self.whitening_matrix().T

    def chi_square_rows(self, rows: np.ndarray, extra: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`DiagonalNoise.chi_square_rows`: one Cholesky factor per row."""
        extra_rows = np.broadcast_to(np.asarray(extra, float), rows.shape)
        out = np.empty((2, len(rows)))
        for w, row in enumerate(rows):
            z, out[1, w] = self.whiten(row, extra_rows[w])
            out[0, w] = float(np.dot(z, z))
        return out[0], out[1]

    def draw(self, rng: np.random.Generator, rows: int) -> np.ndarray:
        """``rows`` draws of the errors, shape (rows, n)."""
        return rng.standard_normal((rows, len(self.cholesky))) @ self.cholesky.T

    def loo(self, rows: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
        """Log density of each value given the others, for residual rows (W, n) (the
        leave-one-out conditionals of :meth:`gonio.fitting.FitProblem.pointwise_log_likelihood`);
        ``extra``: the extra variance, one row per residual row or shared."""
        if np.all(np.asarray(extra) == 0.0):
            if self._precision is None:
                self._precision = np.linalg.inv(self.covariance)
            return _conditionals(rows @ self._precision, np.diag(self._precision))
        extra_rows = np.broadcast_to(np.asarray(extra, float), rows.shape)
        out = np.empty(rows.shape)
        for w, (row, added) in enumerate(zip(rows, extra_rows)):  # one inverse per row
            precision = np.linalg.inv(self.covariance + np.diag(added))
            out[w] = _conditionals(precision @ row, np.diag(precision))
        return out


def _conditionals(g: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``log N`` of each value given the others from ``g = Q r`` and ``q = diag Q``
    (Buerkner, Gabry & Vehtari 2021, eq 7-8)."""
    return -0.5 * np.log(2.0 * math.pi / q) - 0.5 * g**2 / q


class LowRankNoise:
    """Errors of a :class:`LowRankCovariance`: whitening, log-determinant, draws and
    leave-one-out conditionals in O(n k^2) through the Woodbury identity (module notes)."""

    correlated = True

    def __init__(self, covariance: LowRankCovariance) -> None:
        self.covariance = covariance
        self._base = _Woodbury(covariance.independent, covariance.factors)
        self.half_log_det = self._base.half_log_det

    def _with(self, extra: np.ndarray | float) -> "_Woodbury":
        if np.all(np.asarray(extra) == 0.0):
            return self._base
        return _Woodbury(self.covariance.independent + extra, self.covariance.factors)

    def whiten(self, difference: np.ndarray, extra: np.ndarray | float = 0.0) -> tuple[np.ndarray, float]:
        """``W difference`` ((n,) or (n, K)) with ``W C W^T = I`` (``C`` plus the extra
        variance on its diagonal) and ``1/2 log det C``."""
        woodbury = self._with(extra)
        return woodbury.whiten(difference), woodbury.half_log_det

    def whiten_rows(self, rows: np.ndarray) -> np.ndarray:
        """:meth:`whiten` of every row of ``rows`` (W, n)."""
        return self._base.whiten(rows.T).T

    def chi_square_rows(self, rows: np.ndarray, extra: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`DiagonalNoise.chi_square_rows` for many rows at once (in chunks of bounded
        memory): with ``D_w = d + extra_w`` and ``I + U^T D_w^-1 U = L_w L_w^T`` (k x k),
        ``r^T C_w^-1 r = r^T D_w^-1 r - |L_w^-1 U^T D_w^-1 r|^2`` (Woodbury) and
        ``log det C_w = log det D_w + 2 log det L_w`` (the matrix determinant lemma)."""
        extra_rows = np.broadcast_to(np.asarray(extra, float), rows.shape)
        parts = [self._chi_square_chunk(rows[part], extra_rows[part]) for part in self._chunks(len(rows))]
        return (np.concatenate([p[0] for p in parts]) if parts else np.zeros(0),
                np.concatenate([p[1] for p in parts]) if parts else np.zeros(0))

    def _chunks(self, count: int) -> list[slice]:
        """Slices of ``count`` rows whose (rows, n, k) temporaries hold at most
        :data:`CHUNK_ELEMENTS` values (every row at once for a recording's few hundred
        values; one at a time for 1e5 values)."""
        rows = max(1, CHUNK_ELEMENTS // max(self.covariance.n * max(self.covariance.rank, 1), 1))
        return [slice(start, start + rows) for start in range(0, count, rows)]

    def _chi_square_chunk(self, rows: np.ndarray, extra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`chi_square_rows` of one chunk (``extra`` of the rows' shape)."""
        c = self.covariance
        inverse = 1.0 / (c.independent + extra)  # (W, n)
        weighted = rows * inverse
        projected = weighted @ c.factors  # U^T D_w^-1 r, (W, k)
        inner = c.factors.T @ (inverse[:, :, None] * c.factors)  # G_w, (W, k, k)
        diagonal = np.arange(c.rank)
        inner[:, diagonal, diagonal] += 1.0
        factor = np.linalg.cholesky(inner)
        solved = np.linalg.solve(factor, projected[..., None])[..., 0]
        chi2 = (weighted * rows).sum(axis=-1) - (solved * solved).sum(axis=-1)
        log_det = np.log(np.diagonal(factor, axis1=1, axis2=2)).sum(axis=-1) * 2.0 - np.log(inverse).sum(axis=-1)
        return chi2, 0.5 * log_det

    def draw(self, rng: np.random.Generator, rows: int) -> np.ndarray:
        """``rows`` draws of the errors, shape (rows, n): independent part plus shared sources."""
        c = self.covariance
        return (rng.standard_normal((rows, c.n)) * np.sqrt(c.independent)
                + rng.standard_normal((rows, c.rank)) @ c.factors.T)

    def loo(self, rows: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
        """Log density of each value given the others, for residual rows (W, n); ``extra``:
        the extra variance, one row per residual row or shared. With ``D_w = d + extra_w``,
        ``I + U^T D_w^-1 U = L_w L_w^T`` and ``X_w = D_w^-1 U L_w^-T``: ``C_w^-1 r =
        D_w^-1 r - X_w X_w^T r`` and ``diag C_w^-1 = 1/D_w - rowsum(X_w^2)``, every row at
        once."""
        if np.all(np.asarray(extra) == 0.0):
            return _conditionals(self._base.solve(rows.T).T, self._base.precision_diagonal())
        extra_rows = np.broadcast_to(np.asarray(extra, float), rows.shape)
        out = np.empty(rows.shape)
        for part in self._chunks(len(rows)):
            out[part] = self._loo_chunk(rows[part], extra_rows[part])
        return out

    def _loo_chunk(self, rows: np.ndarray, extra: np.ndarray) -> np.ndarray:
        """:meth:`loo` of one chunk with extra noise (``extra`` of the rows' shape)."""
        c = self.covariance
        inverse = 1.0 / (c.independent + extra)  # (W, n)
        scaled = inverse[:, :, None] * c.factors  # D_w^-1 U, (W, n, k)
        inner = c.factors.T @ scaled
        diagonal = np.arange(c.rank)
        inner[:, diagonal, diagonal] += 1.0
        factor = np.linalg.cholesky(inner)  # L_w
        x = np.linalg.solve(factor, scaled.transpose(0, 2, 1)).transpose(0, 2, 1)  # X_w, (W, n, k)
        g = inverse * rows - np.einsum("wnk,wk->wn", x, np.einsum("wnk,wn->wk", x, rows))
        return _conditionals(g, inverse - np.einsum("wnk,wnk->wn", x, x))


class _Woodbury:
    """The factorisation of ``diag(d) + U U^T`` behind :class:`LowRankNoise` (module notes)."""

    def __init__(self, independent: np.ndarray, factors: np.ndarray) -> None:
        self.root = np.sqrt(independent)
        self.v = factors / self.root[:, None]
        gram = self.v.T @ self.v
        s2, r = np.linalg.eigh(gram)
        s2 = np.maximum(s2, 0.0)
        t = np.sqrt(1.0 + s2)
        self._m = (r / (t * (t + 1.0))) @ r.T  # R diag(1/(t(t+1))) R^T
        self._inner = (r / (1.0 + s2)) @ r.T  # (I + G)^-1
        self.half_log_det = float(np.sum(np.log(self.root)) + 0.5 * np.sum(np.log1p(s2)))

    def _scaled(self, x: np.ndarray) -> np.ndarray:
        return x / (self.root if x.ndim == 1 else self.root[:, None])

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """``(I - V M V^T) D^-1/2 x`` for x (n,) or (n, K)."""
        y = self._scaled(np.asarray(x, float))
        return y - self.v @ (self._m @ (self.v.T @ y))

    def solve(self, x: np.ndarray) -> np.ndarray:
        """``C^-1 x`` for x (n,) or (n, K)."""
        y = self._scaled(np.asarray(x, float))
        return self._scaled(y - self.v @ (self._inner @ (self.v.T @ y)))

    def precision_diagonal(self) -> np.ndarray:
        """The diagonal of ``C^-1``, shape (n,)."""
        return (1.0 - np.einsum("nk,nk->n", self.v @ self._inner, self.v)) / self.root**2


def noise_of(sigma: np.ndarray, covariance: Any) -> DiagonalNoise | DenseNoise | LowRankNoise:
    """The likelihood's noise for a dataset's ``sigma`` and ``covariance`` (None, an (n, n)
    array or a :class:`LowRankCovariance`)."""
    if covariance is None:
        return DiagonalNoise(sigma)
    if isinstance(covariance, LowRankCovariance):
        return LowRankNoise(covariance)
    return DenseNoise(covariance)

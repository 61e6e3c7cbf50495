"""Proper prior distributions for the Bayesian fit.

Default priors (:func:`default_prior`), read from each parameter's physical bounds:

* both bounds finite: **uniform** over the bounds (every physically allowed value equally
  likely a priori, e.g. rho in [0, 1], sigma in [0, 90] deg);
* a bound is infinite (the free ``scale`` of relative radiance, which is positive without
  upper limit): **log-uniform** over six decades centred on a reference value (the
  least-squares estimate), i.e. [ref/1000, ref*1000] within the bounds.  The data fix the
  scale to a few per cent, so the width of this window does not matter; it is there so
  that the prior is proper (normalisable) and the evidence is defined.

Any prior can be overridden, in Python with the classes below or on the command line with
``name=uniform:LO:HI``, ``name=loguniform:LO:HI`` or ``name=normal:MEAN:SD`` (see
:func:`parse_prior`).  A prior is always intersected with the physical bounds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

__all__ = ["Prior", "Uniform", "LogUniform", "Normal", "default_prior", "parse_prior", "prior_from_dict"]


class Prior:
    """Base class: a proper, normalised one-dimensional prior density."""

    lower: float
    upper: float

    def logpdf(self, x: float) -> float:  # pragma: no cover - abstract
        """Natural log of the density at ``x`` (``-inf`` outside the support)."""
        raise NotImplementedError

    def logpdf_array(self, x: np.ndarray) -> np.ndarray:
        """:meth:`logpdf` of every element of ``x`` (the ensemble sampler's walkers at once)."""
        return np.array([self.logpdf(float(v)) for v in np.ravel(x)]).reshape(np.shape(x))

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:  # pragma: no cover
        """``size`` independent draws."""
        raise NotImplementedError

    def quantile(self, u: np.ndarray) -> np.ndarray:  # pragma: no cover
        """The inverse of the prior's cumulative distribution at ``u`` in [0, 1] (elementwise):
        maps the unit interval onto the prior (the evidence's sampler works there)."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover
        """JSON form: ``{"kind": ..., parameters}``."""
        raise NotImplementedError

    def width(self) -> float:
        """A characteristic width of the prior (for starting walkers and scaling)."""
        return self.upper - self.lower

    def contains(self, x: float) -> bool:
        """True where the density is positive."""
        return bool(self.lower <= x <= self.upper) and math.isfinite(self.logpdf(x))


def _check_interval(kind: str, lower: float, upper: float) -> None:
    if not (math.isfinite(lower) and math.isfinite(upper)) or not lower < upper:
        raise ValueError(
            f"{kind} prior needs finite bounds with lower < upper, got [{lower:g}, {upper:g}]"
        )


@dataclass(frozen=True)
class Uniform(Prior):
    """Uniform density on [lower, upper]."""

    lower: float
    upper: float

    def __post_init__(self) -> None:
        _check_interval("uniform", self.lower, self.upper)

    def logpdf(self, x: float) -> float:
        if self.lower <= x <= self.upper:
            return -math.log(self.upper - self.lower)
        return -math.inf

    def logpdf_array(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        return np.where((x >= self.lower) & (x <= self.upper), -math.log(self.upper - self.lower), -math.inf)

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        return rng.uniform(self.lower, self.upper, size)

    def quantile(self, u: np.ndarray) -> np.ndarray:
        return self.lower + np.asarray(u, float) * (self.upper - self.lower)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "uniform", "lower": self.lower, "upper": self.upper}

    def __str__(self) -> str:
        return f"uniform({self.lower:g}, {self.upper:g})"


@dataclass(frozen=True)
class LogUniform(Prior):
    """Density proportional to 1/x on [lower, upper], 0 < lower < upper (scale-free)."""

    lower: float
    upper: float

    def __post_init__(self) -> None:
        _check_interval("log-uniform", self.lower, self.upper)
        if self.lower <= 0:
            raise ValueError(f"log-uniform prior needs lower > 0, got {self.lower:g}")

    def logpdf(self, x: float) -> float:
        if self.lower <= x <= self.upper:
            return -math.log(x) - math.log(math.log(self.upper / self.lower))
        return -math.inf

    def logpdf_array(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        inside = (x >= self.lower) & (x <= self.upper)
        with np.errstate(divide="ignore", invalid="ignore"):
            values = -np.log(x) - math.log(math.log(self.upper / self.lower))
        return np.where(inside, values, -math.inf)

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        return np.exp(rng.uniform(math.log(self.lower), math.log(self.upper), size))

    def quantile(self, u: np.ndarray) -> np.ndarray:
        return self.lower * np.exp(np.asarray(u, float) * math.log(self.upper / self.lower))

    def width(self) -> float:
        return math.sqrt(self.lower * self.upper)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "loguniform", "lower": self.lower, "upper": self.upper}

    def __str__(self) -> str:
        return f"log-uniform({self.lower:g}, {self.upper:g})"


@dataclass(frozen=True)
class Normal(Prior):
    """Gaussian density N(mean, sd) truncated to [lower, upper] and renormalised."""

    mean: float
    sd: float
    lower: float = -math.inf
    upper: float = math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mean) and math.isfinite(self.sd) and self.sd > 0):
            raise ValueError(f"normal prior needs a finite mean and sd > 0, got mean={self.mean:g}, sd={self.sd:g}")
        if not self.lower < self.upper:
            raise ValueError(f"normal prior truncation needs lower < upper, got [{self.lower:g}, {self.upper:g}]")
        mass = _normal_cdf((self.upper - self.mean) / self.sd) - _normal_cdf((self.lower - self.mean) / self.sd)
        if mass <= 1e-12:
            raise ValueError(
                f"normal prior N({self.mean:g}, {self.sd:g}) has no mass inside [{self.lower:g}, {self.upper:g}]"
            )
        object.__setattr__(self, "_log_norm", -math.log(self.sd * math.sqrt(2 * math.pi) * mass))

    def logpdf(self, x: float) -> float:
        if self.lower <= x <= self.upper:
            z = (x - self.mean) / self.sd
            return self._log_norm - 0.5 * z * z  # type: ignore[attr-defined]
        return -math.inf

    def logpdf_array(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        z = (x - self.mean) / self.sd
        inside = (x >= self.lower) & (x <= self.upper)
        return np.where(inside, self._log_norm - 0.5 * z * z, -math.inf)  # type: ignore[attr-defined]

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        out = rng.normal(self.mean, self.sd, size)
        bad = (out < self.lower) | (out > self.upper)
        while bad.any():
            out[bad] = rng.normal(self.mean, self.sd, int(bad.sum()))
            bad = (out < self.lower) | (out > self.upper)
        return out

    def quantile(self, u: np.ndarray) -> np.ndarray:
        """Inverse CDF of the truncated normal, on the mirrored side when the truncation lies
        above the mean (no precision lost in the upper tail)."""
        from scipy.special import ndtr, ndtri

        u = np.asarray(u, float)
        alpha, beta = (self.lower - self.mean) / self.sd, (self.upper - self.mean) / self.sd
        if alpha > 0.0:
            low, high = ndtr(-alpha), ndtr(-beta)
            x = self.mean - self.sd * ndtri(low - u * (low - high))
        else:
            low, high = ndtr(alpha), ndtr(beta)
            x = self.mean + self.sd * ndtri(low + u * (high - low))
        return np.clip(x, self.lower, self.upper)  # a limit many sd away: Phi underflows to 0 there

    def width(self) -> float:
        return min(self.sd, self.upper - self.lower)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "normal", "mean": self.mean, "sd": self.sd, "lower": self.lower, "upper": self.upper}

    def __str__(self) -> str:
        text = f"normal({self.mean:g}, {self.sd:g})"
        if math.isfinite(self.lower) or math.isfinite(self.upper):
            text += f" on [{self.lower:g}, {self.upper:g}]"
        return text


def _normal_cdf(z: float) -> float:
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


def default_prior(name: str, bounds: tuple[float, float], reference: float) -> Prior:
    """The default prior of a parameter from its physical bounds (module docstring).

    Parameters
    ----------
    name : str
        Parameter name (for error messages).
    bounds : (float, float)
        Physical range.
    reference : float
        A typical value (the least-squares estimate), used only when a bound is infinite.
    """
    lower, upper = bounds
    if math.isfinite(lower) and math.isfinite(upper):
        return Uniform(lower, upper)
    if lower >= 0 and math.isfinite(reference) and reference > 0:
        lo = max(reference / 1000.0, lower) if lower > 0 else reference / 1000.0
        hi = min(reference * 1000.0, upper)
        return LogUniform(lo, hi)
    scale = 10.0 * abs(reference) + 1.0
    return Normal(reference, scale, lower, upper)


def parse_prior(text: str, bounds: tuple[float, float] = (-math.inf, math.inf)) -> Prior:
    """Parse ``uniform:LO:HI``, ``loguniform:LO:HI`` or ``normal:MEAN:SD``.

    The result is intersected with ``bounds`` (the parameter's physical range).

    Examples
    --------
    >>> str(parse_prior("normal:30:5", (0, 90)))
    'normal(30, 5) on [0, 90]'
    """
    kind, *numbers = [part.strip() for part in text.split(":")]
    try:
        a, b = (float(x) for x in numbers)
    except ValueError:
        raise ValueError(
            f"prior {text!r}: expected uniform:LO:HI, loguniform:LO:HI or normal:MEAN:SD"
        ) from None
    kind = kind.lower().replace("-", "").replace("_", "")
    lower, upper = bounds
    if kind == "uniform":
        return Uniform(max(a, lower), min(b, upper))
    if kind == "loguniform":
        return LogUniform(max(a, lower), min(b, upper))
    if kind in ("normal", "gaussian"):
        return Normal(a, b, lower, upper)
    raise ValueError(f"prior {text!r}: unknown kind {kind!r}; use uniform, loguniform or normal")


def prior_from_dict(data: Mapping[str, Any]) -> Prior:
    """Inverse of ``Prior.to_dict``."""
    kind = data.get("kind")
    if kind == "uniform":
        return Uniform(float(data["lower"]), float(data["upper"]))
    if kind == "loguniform":
        return LogUniform(float(data["lower"]), float(data["upper"]))
    if kind == "normal":
        # strict JSON has no infinity: an unbounded side is stored as null
        lower = -math.inf if data.get("lower") is None else float(data["lower"])
        upper = math.inf if data.get("upper") is None else float(data["upper"])
        return Normal(float(data["mean"]), float(data["sd"]), lower, upper)
    raise ValueError(f"prior record {dict(data)!r}: unknown kind {kind!r}")

"""A tabulated model's fit polished with the exact model where the table's error matters.

``oren-nayar-tabulated`` interpolates the exact V-cavity model (docs/tabulated.md): about
1e-4 relative error (median; 5.5e-4 at the 99th percentile), three orders of magnitude
faster. Against a real lab's noise (0.15-0.6 %) that error is a tenth of the noise or less
and changes nothing; against a rig that measures to 1e-4 it is several standard
deviations of the data, and the table's posterior misses the truth (sigma covered 0 of 10
times on the idealised rig).

:func:`table_error` measures the table's error at the fit's own geometries, in units of
the data's uncertainties (rms of ``(table - exact) / sigma`` at the least-squares optimum).
Where it exceeds :data:`POLISH_LIMIT`, :func:`polish` moves the optimum to the exact
model's (least squares with ``oren-nayar-exact`` from the table's optimum, one start) and
the posterior by the same shift: the table's posterior has the shape of the exact one
(their curvatures differ by the table's error, a part in 1e3) but sits where the table's
error puts it. The shift is reported in the fit's flags.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

import numpy as np

__all__ = ["POLISH_LIMIT", "EXACT_OPTIONS", "Polish", "exact_reference", "exact_problem", "table_error", "with_table_error", "polish", "shifted_chain"]

#: Table error (rms, in units of the data's uncertainties) above which a fit is polished.
POLISH_LIMIT = 0.1
#: Options of the exact model where it measures a table's error (:func:`table_error`; the
#: polish itself fits it at its default accuracy): rtol 1e-5 is within 3.6e-6 of the exact
#: value (gonio.models.oren_nayar.exact), a sixtieth of the table's own error (2.2e-4 rms
#: at sigma = 30 deg), and takes 0.6 of the time of its 1e-6 default at the demo's 126
#: values (0.08409 against 0.08411 x the uncertainties there).
EXACT_OPTIONS: dict[str, dict[str, float]] = {"oren-nayar-exact": {"rtol": 1e-5}}


@dataclass(frozen=True)
class Polish:
    """The exact model's least-squares fit and the shift it applies to the table's.

    Attributes
    ----------
    exact : str
        The exact model's name.
    table_error : float
        rms of (table - exact) / sigma at the table's optimum [-].
    least_squares : LeastSquaresResult
        The exact model's fit.
    shift : dict
        Exact minus table optimum, by free parameter.
    problem : FitProblem
        The exact model's problem (the fit's goodness of fit is judged under it).
    """

    exact: str
    table_error: float
    least_squares: Any
    shift: dict[str, float]
    problem: Any

    def flag(self) -> str:
        """The line the fit's flags carry."""
        moved = ", ".join(f"{name} {value:+.3g}" for name, value in self.shift.items() if value)
        return (f"polished with {self.exact}: the table's error at these geometries is {self.table_error:.2g} x the "
                f"uncertainties (rms); the optimum and the posterior moved by {moved or 'nothing'}")


def exact_reference(model: str) -> str | None:
    """The exact model a tabulated model interpolates (its table's ``reference``,
    :data:`gonio.models.tabulated.TABLES`), or None for a model read from no table."""
    from gonio.models.tabulated import TABLES

    return next((table.reference for table in TABLES.values() if table.model == model), None)


def table_error(problem, exact_problem, values: Mapping[str, float]) -> float:
    """rms of (table - exact) / sigma at ``values`` (module docstring)."""
    difference = problem.predict(values) - exact_problem.predict(values)
    return float(np.sqrt(np.mean((difference / problem.dataset.sigma) ** 2)))


def with_table_error(problem, least_squares, build_problem):
    """``least_squares`` with its :attr:`~gonio.fitting.least_squares.LeastSquaresResult.table_error`
    measured: itself for a model read from no table or an error already measured, else a
    copy carrying :func:`table_error` at its optimum (one evaluation of the exact model at
    every value's geometry).

    Parameters
    ----------
    problem : FitProblem
        The tabulated model's problem.
    least_squares : LeastSquaresResult
        Its fit.
    build_problem : callable
        ``build_problem(model_name)`` -> the same problem with another model.
    """
    exact = exact_reference(problem.base_model.name)
    if exact is None or math.isfinite(least_squares.table_error):
        return least_squares
    return replace(least_squares, table_error=table_error(problem, exact_problem(build_problem, exact),
                                                          least_squares.values))


def exact_problem(build_problem, exact: str):
    """The problem of the exact model ``exact`` with its :data:`EXACT_OPTIONS`."""
    built = build_problem(exact)
    options = EXACT_OPTIONS.get(exact)
    return built.fixing(options=options) if options else built


def polish(problem, least_squares, priors, build_problem) -> Polish | None:
    """The exact model's optimum, when the table's error matters (module docstring).

    Parameters
    ----------
    problem : FitProblem
        The tabulated model's problem.
    least_squares : LeastSquaresResult
        Its fit; its ``table_error``, where already measured (:func:`with_table_error`),
        is used instead of evaluating the exact model again.
    priors : mapping of Prior
        The fit's priors.
    build_problem : callable
        ``build_problem(model_name)`` -> the same problem with another model.

    Returns
    -------
    Polish or None
        None for a model without an exact reference, or a table error within
        :data:`POLISH_LIMIT`.
    """
    from .least_squares import fit_least_squares

    exact = exact_reference(problem.base_model.name)
    if exact is None:
        return None
    error = with_table_error(problem, least_squares, build_problem).table_error
    if not error > POLISH_LIMIT:
        return None
    polished = build_problem(exact)  # at its default accuracy: the fit moves by what the table misses
    fitted = fit_least_squares(polished, start=least_squares.values, n_starts=1, priors=priors)
    shift = {name: fitted.values[name] - least_squares.values[name] for name in problem.free}
    return Polish(exact, error, fitted, shift, polished)


def shifted_chain(mcmc, problem, shift: Mapping[str, float]):
    """The chain moved by ``shift``, each value kept inside its physical range."""
    vector = np.array([shift[name] for name in mcmc.free])
    chain = mcmc.chain + vector
    for k, name in enumerate(mcmc.free):
        low, high = problem.spec(name).bounds
        chain[..., k] = np.clip(chain[..., k], low if math.isfinite(low) else -np.inf,
                                high if math.isfinite(high) else np.inf)
    return replace(mcmc, chain=chain)

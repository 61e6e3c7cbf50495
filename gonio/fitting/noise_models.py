"""How much a fit's parameters depend on the noise model, for data without stated errors.

A measured set with stated uncertainties (a reduced recording) fixes the weights of its
fit. Data published without them (CUReT) get an estimated noise (gonio.curet: relative to
each value, scaled by the scatter about a smooth series), and the shape of that estimate
is a choice: with the same formula and data, reasonable shapes move the parameters (on
CUReT sample 30, sigma ranged from 25.4 to 32.7 deg over such choices, where one fit's
interval was [29.3, 33.8] deg). That spread is a systematic part of the parameters'
uncertainty that no single likelihood shows.

:func:`noise_model_spread` refits a model by least squares under the shapes of
:data:`NOISE_SHAPES`, each scaled to the dataset's median uncertainty, all three of which a
camera measurement has in some mixture (Janesick 2007, ch. 2: photon shot noise, gain and
calibration, read noise):

``relative``
    proportional to the value (gain, calibration, the lamp): the estimate's own shape;
``shot``
    proportional to the square root of the value (photon noise);
``absolute``
    the same for every value (read noise, stray light).

and reports, per parameter, each shape's value and half the range they span: the
noise-model component, to be added in quadrature to the interval of any one of them
(``gonio curet fit`` prints it beside the fits and writes it to ``comparison.json``).

References
----------
J. R. Janesick, "Photon Transfer", SPIE Press (2007), chapter 2.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .dataset import Dataset

__all__ = ["NOISE_SHAPES", "NoiseModelSpread", "noise_model_spread", "reweighted"]

#: The shapes of the uncertainty tried, as a function of the values' magnitude.
NOISE_SHAPES = ("relative", "shot", "absolute")


@dataclass(frozen=True)
class NoiseModelSpread:
    """Least-squares parameters under every noise shape and their spread.

    Attributes
    ----------
    values : dict
        ``{shape: {parameter: value}}``.
    half_range : dict
        ``{parameter: (max - min) / 2}`` over the shapes: the noise-model component.
    """

    values: dict[str, dict[str, float]]
    half_range: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"shapes": list(self.values), "values": self.values, "half_range": self.half_range}

    def lines(self) -> list[str]:
        """A plain-text table: one row per parameter."""
        names = list(self.half_range)
        header = f"    {'parameter':<14}" + "".join(f"{shape:>12}" for shape in self.values) + f"{'half range':>12}"
        rows = [header]
        for name in names:
            rows.append(f"    {name:<14}" + "".join(f"{v[name]:>12.5g}" for v in self.values.values())
                        + f"{self.half_range[name]:>12.3g}")
        return rows


def reweighted(dataset: Dataset, shape: str) -> Dataset:
    """The dataset with uncertainties of ``shape`` scaled to its median uncertainty.

    Examples
    --------
    >>> data = Dataset(30, 0, [0, 20, 40], 0, [4.0, 1.0, 0.25], 0.1)
    >>> [round(float(s), 3) for s in reweighted(data, "shot").sigma]
    [0.2, 0.1, 0.05]
    """
    if shape not in NOISE_SHAPES:
        raise ValueError(f"noise shape {shape!r} is not one of {list(NOISE_SHAPES)}")
    magnitude = np.maximum(np.abs(dataset.value), 1e-12 * np.max(np.abs(dataset.value)))
    profile = {"relative": magnitude, "shot": np.sqrt(magnitude), "absolute": np.ones_like(magnitude)}[shape]
    sigma = profile * np.median(dataset.sigma) / np.median(profile)
    return Dataset(*dataset.geometry, dataset.value, sigma, quantity=dataset.quantity, label=dataset.label,
                   metadata=dataset.metadata)


def noise_model_spread(dataset: Dataset, model: str, fixed: Mapping[str, float] | None = None,
                       jitter: bool | str = False) -> NoiseModelSpread:
    """Fit ``model`` under every shape of :data:`NOISE_SHAPES` (module docstring).

    Parameters
    ----------
    dataset : Dataset
    model : str
    fixed : mapping, optional
        Fixed parameters.
    jitter : bool or {"absolute", "relative"}
        The extra-noise term of every fit (as the main fit has).
    """
    from .least_squares import fit_least_squares
    from .problem import FitProblem

    values = {}
    for shape in NOISE_SHAPES:
        problem = FitProblem(model, reweighted(dataset, shape), fixed, jitter=jitter)
        least_squares = fit_least_squares(problem, priors=problem.priors_with_defaults(None))
        values[shape] = {name: float(least_squares.values[name]) for name in problem.free}
    names = list(values[NOISE_SHAPES[0]])
    half_range = {name: 0.5 * (max(v[name] for v in values.values()) - min(v[name] for v in values.values()))
                  for name in names}
    return NoiseModelSpread(values, half_range)

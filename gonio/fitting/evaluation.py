"""How a fit evaluates a model: as the measured quantity, through the rig's apertures.

The bottom of :mod:`gonio.fitting`'s prediction path, shared by the fit problem
(:mod:`gonio.fitting.problem`), the rig's errors (:mod:`gonio.fitting.rig_errors`), the
compiled misaligned rig (:mod:`gonio.fitting.compiled_rig`) and the results: the formula
from model BRDF to the measured quantity (:func:`combine_prediction`), the model a dataset
is fitted with (:func:`evaluated_model`, averaged over the apertures its metadata names,
:func:`apertures_of`), and the models the compiled misaligned-rig loop knows
(:data:`COMPILED_MODELS`). It imports nothing else of the fitting package.
"""
from __future__ import annotations

import json
from typing import Any, Mapping

import numpy as np

from gonio import models
from gonio.models import Model

from .dataset import Dataset

__all__ = ["combine_prediction", "evaluated_model", "apertures_of", "COMPILED_MODELS"]

#: Models whose misaligned aperture average has a compiled path (gonio.fitting.compiled_rig).
COMPILED_MODELS = ("oren-nayar", "lambert", "oren-nayar-qualitative", "oren-nayar-tabulated",
                   "oren-nayar+torrance-sparrow")


def combine_prediction(
    quantity: str, brdf: np.ndarray, brdf_normal_view: np.ndarray | None, cos_theta_i: np.ndarray, scale: float
) -> np.ndarray:
    """The measured quantity predicted from model BRDF values (one formula, two callers).

    Parameters
    ----------
    quantity : {'brdf', 'normalised_radiance', 'radiance'}
        See :mod:`gonio.fitting.dataset`.
    brdf : ndarray
        Model BRDF at the measurement geometry [1/sr].
    brdf_normal_view : ndarray or None
        Model BRDF at the normal view (theta_r = 0) of the same incidence [1/sr]; needed
        for ``normalised_radiance``.
    cos_theta_i : ndarray
        Cosine of the incidence angle [-] (for ``radiance``).
    scale : float
        Free scale of relative radiance [data units sr].

    Returns
    -------
    ndarray
        Predicted values.  For normalised radiance where the normal-view BRDF is 0 (a
        black sample) the ratio is undefined and NaN is returned (no warning).

    Notes
    -----
    Normalised radiance L_r(theta_r)/L_r(0) for a fixed source equals f_r(theta_r)/f_r(0)
    because L_r = f_r E_0 cos(theta_i) (Oren & Nayar 1995, section 5, discussion of
    Fig 16); the factor E_0 cos(theta_i) cancels.
    """
    if quantity == "brdf":
        return brdf
    if quantity == "radiance":
        return scale * brdf * cos_theta_i
    out = np.full(np.shape(brdf), np.nan)
    np.divide(brdf, brdf_normal_view, out=out, where=brdf_normal_view > 0)
    return out


def evaluated_model(model: str | Model, dataset: Dataset) -> Model:
    """The model a fit of ``dataset`` evaluates: ``model`` itself, or its average over the
    instrument's apertures when the dataset carries them (``metadata["aperture_sr"]`` =
    [lamp, camera] solid angles [sr]; :func:`gonio.instrument.aperture_averaged`)."""
    base = models.get(model) if isinstance(model, str) else model
    aperture = apertures_of(dataset.metadata)
    if not aperture:
        return base
    from gonio.instrument import aperture_averaged

    return aperture_averaged(base, *aperture)


def apertures_of(metadata: Mapping[str, Any] | None) -> list[float] | None:
    """The [lamp, camera] solid angles [sr] of a dataset's ``metadata["aperture_sr"]`` (a
    list, or its JSON text as a CSV header line gives it back), or None."""
    aperture = metadata.get("aperture_sr") if metadata else None
    if isinstance(aperture, str):  # read back from a CSV header line "# aperture_sr: [..]"
        try:
            aperture = json.loads(aperture)
        except json.JSONDecodeError:
            raise ValueError(f"dataset metadata aperture_sr = {aperture!r}: expected [lamp, camera] "
                             "solid angles in sr, e.g. [0.003, 0.0009]") from None
    return list(aperture) if aperture else None

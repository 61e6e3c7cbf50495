"""The registered closed-form Oren-Nayar models: ``oren-nayar`` (eq 33-35) and
``oren-nayar-qualitative`` (eq 36).

Each :class:`~gonio.models.Model` joins its formula in numpy
(:mod:`gonio.models.oren_nayar.functional`, whose docstring says what the models are;
for ``oren-nayar`` also its plain-Python small call and its allocation-free large call)
with its compiled plain call (:mod:`gonio.models.oren_nayar.compiled`, loaded with numba on
first use). The formulas sit below both: this module is the only one that knows the two.
"""
from __future__ import annotations

from .._core import Model, register
from .functional import (IR_WEIGHT, RHO, SIGMA, VARIANT, _oren_nayar_fill, _oren_nayar_point, _prepare_oren_nayar,
                         _prepare_qualitative)

__all__ = ["OREN_NAYAR", "OREN_NAYAR_QUALITATIVE"]


def _compiled_oren_nayar():
    """The compiled plain call of ``oren-nayar`` (numba loads here, on first use)."""
    from .compiled import oren_nayar_plain

    return oren_nayar_plain


def _compiled_qualitative():
    """The compiled plain call of ``oren-nayar-qualitative`` (numba loads here)."""
    from .compiled import qualitative_plain

    return qualitative_plain


OREN_NAYAR = register(
    Model(
        name="oren-nayar",
        params=(RHO, SIGMA, IR_WEIGHT),
        reference="Oren & Nayar 1995, section 4.3, eq 33-35 (functional approximation with interreflection)",
        description="rough diffuse surface: Oren-Nayar functional approximation with interreflection",
        prepare=_prepare_oren_nayar,
        energy_conserving=False,
        broadcasts_params=True,
        compiled=_compiled_oren_nayar,
        point=_oren_nayar_point,
        fill=_oren_nayar_fill,
    )
)

OREN_NAYAR_QUALITATIVE = register(
    Model(
        name="oren-nayar-qualitative",
        params=(RHO, SIGMA),
        reference="Oren & Nayar 1995, section 4.4, eq 36 and footnote 11 (qualitative model)",
        description="rough diffuse surface: simplified Oren-Nayar model (A + B sin(alpha) tan(beta))",
        prepare=_prepare_qualitative,
        options=(VARIANT,),
        energy_conserving=False,
        linear_in=("rho",),
        broadcasts_params=True,
        compiled=_compiled_qualitative,
    )
)

"""``--realism`` of ``gonio emulator``, ``gonio run`` and ``gonio demo``: the emulated rig's
systematic errors as a spec (:func:`drivers.emulator.systematics.realism`)."""
from __future__ import annotations

from typing import Any

from . import CLIError

__all__ = ["REALISM_SYNTAX", "REALISM_HELP", "parse_realism", "realism_metadata"]

#: The forms ``--realism`` takes (drivers.emulator.systematics.realism).
REALISM_SYNTAX = "ideal|lab[:name=value,...]"
REALISM_HELP = ("systematic errors of the emulated rig: 'ideal' (none, the default), 'lab' (typical magnitudes: axis "
                "zero offsets and sample tilt drawn from the seed, stray light, camera non-linearity, lamp beam "
                "profile), either with overrides such as lab:stray_light=0 (docs/emulator.md, 'Systematic errors')")


def parse_realism(spec: str, seed: int) -> Any:
    """The :class:`drivers.emulator.systematics.Systematics` of a ``--realism`` spec.

    Raises
    ------
    CLIError
        Naming what was wrong and what was expected.
    """
    from drivers.emulator.systematics import realism

    try:
        return realism(spec, seed)
    except ValueError as error:
        raise CLIError(f"--realism: {error}") from None


def realism_metadata(spec: str, systematics: Any) -> dict[str, Any]:
    """What a recording stores of the rig's realism: the spec and every magnitude it gave."""
    return {"spec": spec, **systematics.to_dict()}

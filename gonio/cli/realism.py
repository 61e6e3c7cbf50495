"""``--realism`` of ``gonio emulator``, ``gonio run`` and ``gonio demo``: the emulated rig's
systematic errors as a spec (:func:`drivers.emulator.systematics.realism`)."""
from __future__ import annotations

from typing import Any

from . import CLIError

__all__ = ["REALISM_SYNTAX", "REALISM_HELP", "DEFAULT_REALISM", "IDEAL_RIG_NOTE", "parse_realism", "realism_metadata"]

#: The emulated rig's realism when none is given: a real lab's rig.
DEFAULT_REALISM = "lab"
#: What a command says when it runs the idealised rig.
IDEAL_RIG_NOTE = ("note: the emulated rig is IDEALISED (--realism ideal): no misalignment, stray light, "
                  "non-linearity, beam profile, sample texture or remounting; its precision (about 1e-4) is 10 "
                  "to 100 times what a real gonioreflectometer achieves. Use it for studies, not as a stand-in "
                  "for a real measurement")
#: The forms ``--realism`` takes (drivers.emulator.systematics.realism).
REALISM_SYNTAX = "ideal|lab[:name=value,...]"
REALISM_HELP = ("the emulated rig's departures from the ideal: 'lab' (the default: what a careful lab sees: axis "
                "zero offsets and holder tilt drawn from the seed, stray light, camera non-linearity, lamp beam "
                "profile, the sample's texture and wedge, remounting, a lamp monitor that does not see the "
                "sample's beam exactly) or 'ideal' (none: an idealised rig for studies), either with overrides "
                "such as lab:stray_light=0 (docs/emulator.md, 'Systematic errors' and 'The sample as labs meet "
                "it')")


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

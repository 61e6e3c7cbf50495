"""A protocol measured on the in-process emulated rig into a recording folder (for tests)."""
from __future__ import annotations

from pathlib import Path

from gonio import acquisition, protocols
from gonio.cli.run import emulated_rig


def record(folder: Path, text: str, sample: str, seed: int, realism: str = "ideal", resume: bool = False) -> Path:
    """Measure the protocol ``text`` on an emulated rig of ``sample`` (a sample spec),
    ``seed`` and ``realism`` into ``folder`` (``resume``: continue the recording there),
    its reference standard (if any) swapped in by the emulator's holder; the lamp starts
    warm."""
    protocol = protocols.loads(text, source=f"{folder.name}.toml")
    reflectance = protocol.reference.reflectance if protocol.reference is not None else 0.99
    with emulated_rig(sample, seed, name=f"test-{folder.name}", realism=realism) as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, resume=resume, metadata=meta, clock=emulator.control.now,
                                 warm_up=False, change_sample=lambda which: change(which, reflectance))
    return folder

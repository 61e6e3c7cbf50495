"""A protocol measured on the in-process emulated rig into a recording folder (for tests)."""
from __future__ import annotations

from pathlib import Path

from gonio import acquisition, protocols
from gonio.cli.run import emulated_rig

#: A Lambertian standard read at six lamp polar angles (10 to 60 deg, camera at -10 deg),
#: with one sample point: the standard's irradiance per angle against its stated
#: covariance (tests/test_linearity_and_beam.py, benchmarks/bench_incidence_deviations.py).
STANDARD_ANGLES = """
[protocol]
name = "standard-angles"
[sample]
label = "plaster"
[[block]]
theta_i = 30
phi_i = 0
view = [0]
[reference]
label = "standard"
reflectance = 0.99
geometries = [[10, 0, -10], [20, 0, -10], [30, 0, -10], [40, 0, -10], [50, 0, -10], [60, 0, -10]]
"""


def record(folder: Path, text: str, sample: str, seed: int, realism: str = "ideal", resume: bool = False) -> Path:
    """Measure the protocol ``text`` on an emulated rig of ``sample`` (a sample spec),
    ``seed`` and ``realism`` into ``folder`` (``resume``: continue the recording there),
    its reference standard (if any) swapped in by the emulator's holder and the sample
    remounted as the protocol's mountings ask; the lamp starts warm."""
    protocol = protocols.loads(text, source=f"{folder.name}.toml")
    reflectance = protocol.reference.reflectance if protocol.reference is not None else 0.99
    with emulated_rig(sample, seed, name=f"test-{folder.name}", realism=realism,
                      remount_time=protocol.rig.remount_time) as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, resume=resume, metadata=meta, clock=emulator.control.now,
                                 warm_up=False, change_sample=lambda which, **how: change(which, reflectance, **how))
    return folder

"""Sweep protocols: the TOML files users write to script a measurement, and their plans.

A protocol names the sample, the rig's limits, how to expose, how often to take dark
frames, an optional reference-standard measurement, and blocks of lamp directions each
with the camera angles to visit.  :func:`load` reads and validates a file (every error
names the file, the field and what was expected); :func:`plan` turns a protocol into the
ordered list of measurement points, lists every point the rig would refuse (travel
limits, camera/lamp separation) with its reason, and estimates the instrument time.

The rig (Oren & Nayar 1995, section 5, Fig 15; our rig motorises the lamp) has three axes:
the camera swings in one plane (signed camera angle ``view``: the camera sits at polar
angle |view| on the azimuth-0 side of that plane for view >= 0, on the azimuth-180 side
for view < 0), the lamp polar angle ``theta_i``, and the lamp azimuth ``phi_i`` measured
about the sample normal from the camera's swing plane.  With phi_i = 0 the camera sweeps
the plane of incidence and ``view`` is the signed viewing angle of DESIGN.md (positive on
the source side).  The rig has no sample-rotation stage, so it realises any pair of
directions up to a common rotation about the normal: for isotropic samples (all the
papers' models) that is every geometry.

The file format is documented in docs/protocols.md.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

from .geometry import angle_between, azimuth_difference

__all__ = [
    "ProtocolError",
    "RigLimits",
    "Exposure",
    "Darks",
    "Reference",
    "Block",
    "Protocol",
    "PlannedPoint",
    "Refusal",
    "Plan",
    "load",
    "loads",
    "plan",
    "rig_coordinates",
]

FORMAT_VERSION = 1
#: Rounding allowance when comparing the camera/lamp separation with its minimum [deg].
SEPARATION_TOLERANCE = 1e-6


class ProtocolError(ValueError):
    """A protocol file is invalid; the message names the file, the field and the problem."""


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class RigLimits:
    """Travel limits, separation rule and timing of the rig (defaults: the emulated rig).

    Attributes
    ----------
    camera_range : tuple of float
        Signed camera angle travel [deg].
    lamp_theta_range : tuple of float
        Lamp polar angle travel [deg].
    lamp_phi_range : tuple of float
        Lamp azimuth travel [deg].
    min_separation : float
        Smallest angle allowed between camera and lamp directions [deg] (their housings).
    velocity : float
        Stage slew speed [deg/s] used for time estimates.
    acceleration : float
        Stage acceleration [deg/s^2] used for time estimates.
    settle_time : float
        Wait after each move before exposing [s].
    readout_time : float
        CCD readout time per frame [s].
    lamp_solid_angle, camera_solid_angle : float
        Apertures of the lamp and of the camera's pupil seen from the sample [sr]
        (Oren & Nayar 1995, section 5: 0.003 and 0.0009); fits of the recording average
        the model over them (gonio.instrument).
    """

    camera_range: tuple[float, float] = (-90.0, 90.0)
    lamp_theta_range: tuple[float, float] = (0.0, 90.0)
    lamp_phi_range: tuple[float, float] = (-180.0, 180.0)
    min_separation: float = 5.0
    velocity: float = 10.0
    acceleration: float = 20.0
    settle_time: float = 0.2
    readout_time: float = 0.1
    lamp_solid_angle: float = 0.003
    camera_solid_angle: float = 0.0009


@dataclass(frozen=True)
class Exposure:
    """Exposure policy.

    ``mode`` is ``"auto"`` (adjust the exposure until the ROI mean sits near
    ``target_fraction`` of full scale with no saturated pixel, starting from ``time``),
    ``"fixed"`` (always ``time``) or ``"hdr"`` (one frame per time in ``brackets``, combined
    from the unsaturated ones).  Times in seconds.
    """

    mode: str = "auto"
    time: float = 0.02
    brackets: tuple[float, ...] = ()
    target_fraction: float = 0.5
    max_time: float = 5.0
    frames: int = 1


@dataclass(frozen=True)
class Darks:
    """Dark frames: at the start, and then every ``every`` points (0 = only at the start)."""

    at_start: bool = True
    every: int = 20


@dataclass(frozen=True)
class Reference:
    """A reference standard of known reflectance measured for absolute BRDF.

    The standard (e.g. a diffuse reflectance standard treated as Lambertian with
    ``reflectance``) is measured at each (theta_i, phi_i, view) in ``geometries``.
    """

    label: str
    reflectance: float
    geometries: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class Block:
    """One lamp direction with the camera angles to visit there.

    Attributes
    ----------
    name : str
        Label shown in plans and recordings.
    theta_i, phi_i : float
        Lamp polar angle and azimuth from the camera's swing plane [deg].
    views : tuple of float
        Signed camera angles [deg] in the order they are visited.
    repeats : int
        How many times the sweep is repeated.
    """

    name: str
    theta_i: float
    phi_i: float
    views: tuple[float, ...]
    repeats: int = 1


@dataclass(frozen=True)
class Protocol:
    """A validated sweep protocol (see :func:`load`)."""

    name: str
    sample: str
    description: str
    metadata: Mapping[str, Any]
    rig: RigLimits
    exposure: Exposure
    darks: Darks
    blocks: tuple[Block, ...]
    reference: Reference | None = None
    source: str = "<string>"
    text: str = ""


# --------------------------------------------------------------------------- parsing
class _Fields:
    """Reads typed fields from a TOML table, raising errors that name file and field."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field_name: str, expected: str, got: Any = None, *, show_got: bool = True) -> ProtocolError:
        tail = f", got {got!r}" if show_got else ""
        return ProtocolError(f"{self.source}: field '{field_name}': expected {expected}{tail}")

    def table(self, data: Mapping, key: str, where: str, required: bool = False) -> Mapping:
        value = data.get(key, None)
        if value is None:
            if required:
                raise self.fail(_join(where, key), "a table", show_got=False)
            return {}
        if not isinstance(value, Mapping):
            raise self.fail(_join(where, key), "a table", value)
        return value

    def unknown(self, data: Mapping, allowed: Iterable[str], where: str) -> None:
        allowed = set(allowed)
        for key in data:
            if key not in allowed:
                import difflib

                hint = difflib.get_close_matches(key, sorted(allowed), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise ProtocolError(
                    f"{self.source}: field '{_join(where, key)}' is not a known field{extra}; "
                    f"known fields here: {sorted(allowed)}"
                )

    def string(self, data: Mapping, key: str, where: str, default: str | None = None) -> str:
        value = data.get(key, default)
        if value is None:
            raise self.fail(_join(where, key), "a string (required)", show_got=False)
        if not isinstance(value, str) or not value.strip():
            raise self.fail(_join(where, key), "a non-empty string", value)
        return value

    def number(
        self, data: Mapping, key: str, where: str, default: float | None = None,
        low: float = -math.inf, high: float = math.inf, unit: str = "",
    ) -> float:
        value = data.get(key, default)
        name = _join(where, key)
        if value is None:
            raise self.fail(name, f"a number{_unit(unit)} (required)", show_got=False)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
            raise self.fail(name, f"a number{_unit(unit)}", value)
        if not low <= value <= high:
            raise self.fail(name, f"a number in [{low:g}, {high:g}]{_unit(unit)}", value)
        return float(value)

    def integer(self, data: Mapping, key: str, where: str, default: int, low: int = 0) -> int:
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise self.fail(_join(where, key), f"an integer >= {low}", value)
        return int(value)

    def boolean(self, data: Mapping, key: str, where: str, default: bool) -> bool:
        value = data.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(_join(where, key), "true or false", value)
        return value

    def pair(self, data: Mapping, key: str, where: str, default: tuple[float, float], unit: str) -> tuple[float, float]:
        value = data.get(key, list(default))
        name = _join(where, key)
        if (not isinstance(value, list) or len(value) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
                or value[0] > value[1]):
            raise self.fail(name, f"[low, high] with low <= high{_unit(unit)}", value)
        return float(value[0]), float(value[1])

    def angles(self, value: Any, name: str) -> tuple[float, ...]:
        """A list of angles, or a range table {start, stop, step} (stop included)."""
        if isinstance(value, list):
            if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                raise self.fail(name, "a non-empty list of angles [deg] or {start, stop, step}", value)
            return tuple(float(v) for v in value)
        if isinstance(value, Mapping):
            self.unknown(value, ("start", "stop", "step"), name)
            start = self.number(value, "start", name, unit="deg")
            stop = self.number(value, "stop", name, unit="deg")
            step = self.number(value, "step", name, low=1e-6, unit="deg")
            count = int(math.floor((stop - start) / step + 1e-9)) + 1 if stop >= start else 0
            if count <= 0:
                raise self.fail(name, "stop >= start", {"start": start, "stop": stop})
            if count > 100_000:
                raise self.fail(name, "at most 100000 angles", f"{count} angles")
            return tuple(round(start + k * step, 10) for k in range(count))
        raise self.fail(name, "a list of angles [deg] or a table {start, stop, step}", value)


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


def loads(text: str, source: str = "<string>") -> Protocol:
    """Parse and validate protocol TOML text (see :func:`load`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ProtocolError(f"{source}: not valid TOML: {error}") from None
    f = _Fields(source)
    f.unknown(data, ("protocol", "sample", "rig", "exposure", "darks", "reference", "block"), "")

    head = f.table(data, "protocol", "", required=True)
    f.unknown(head, ("name", "description", "format_version"), "protocol")
    version = f.integer(head, "format_version", "protocol", FORMAT_VERSION, low=1)
    if version != FORMAT_VERSION:
        raise f.fail("protocol.format_version", f"{FORMAT_VERSION} (the version this gonio reads)", version)
    name = f.string(head, "name", "protocol")
    description = head.get("description", "")
    if not isinstance(description, str):
        raise f.fail("protocol.description", "a string", description)

    sample_table = f.table(data, "sample", "", required=True)
    f.unknown(sample_table, ("label", "metadata"), "sample")
    sample = f.string(sample_table, "label", "sample")
    metadata = f.table(sample_table, "metadata", "sample")

    rig_table = f.table(data, "rig", "")
    f.unknown(rig_table, RigLimits.__dataclass_fields__.keys(), "rig")
    base = RigLimits()
    rig = RigLimits(
        camera_range=f.pair(rig_table, "camera_range", "rig", base.camera_range, "deg"),
        lamp_theta_range=f.pair(rig_table, "lamp_theta_range", "rig", base.lamp_theta_range, "deg"),
        lamp_phi_range=f.pair(rig_table, "lamp_phi_range", "rig", base.lamp_phi_range, "deg"),
        min_separation=f.number(rig_table, "min_separation", "rig", base.min_separation, 0.0, 90.0, "deg"),
        velocity=f.number(rig_table, "velocity", "rig", base.velocity, 1e-6, unit="deg/s"),
        acceleration=f.number(rig_table, "acceleration", "rig", base.acceleration, 1e-6, unit="deg/s^2"),
        settle_time=f.number(rig_table, "settle_time", "rig", base.settle_time, 0.0, unit="s"),
        readout_time=f.number(rig_table, "readout_time", "rig", base.readout_time, 0.0, unit="s"),
        lamp_solid_angle=f.number(rig_table, "lamp_solid_angle", "rig", base.lamp_solid_angle, 0.0, 1.0, "sr"),
        camera_solid_angle=f.number(rig_table, "camera_solid_angle", "rig", base.camera_solid_angle, 0.0, 1.0, "sr"),
    )

    exp_table = f.table(data, "exposure", "")
    f.unknown(exp_table, Exposure.__dataclass_fields__.keys(), "exposure")
    mode = exp_table.get("mode", "auto")
    if mode not in ("auto", "fixed", "hdr"):
        raise f.fail("exposure.mode", "one of 'auto', 'fixed', 'hdr'", mode)
    brackets: tuple[float, ...] = ()
    if mode == "hdr":
        if "brackets" not in exp_table:
            raise f.fail("exposure.brackets", "a list of exposure times [s] (required for mode 'hdr')", show_got=False)
        brackets = f.angles(exp_table["brackets"], "exposure.brackets")
        if any(b <= 0 for b in brackets):
            raise f.fail("exposure.brackets", "positive exposure times [s]", list(brackets))
    elif "brackets" in exp_table:
        raise f.fail("exposure.brackets", "no brackets unless mode = 'hdr'", exp_table["brackets"])
    exposure = Exposure(
        mode=mode,
        time=f.number(exp_table, "time", "exposure", 0.02, 1e-6, 60.0, "s"),
        brackets=brackets,
        target_fraction=f.number(exp_table, "target_fraction", "exposure", 0.5, 0.05, 0.95),
        max_time=f.number(exp_table, "max_time", "exposure", 5.0, 1e-6, 600.0, "s"),
        frames=f.integer(exp_table, "frames", "exposure", 1, low=1),
    )

    dark_table = f.table(data, "darks", "")
    f.unknown(dark_table, ("at_start", "every"), "darks")
    darks = Darks(
        at_start=f.boolean(dark_table, "at_start", "darks", True),
        every=f.integer(dark_table, "every", "darks", 20, low=0),
    )

    reference = None
    ref_table = f.table(data, "reference", "")
    if ref_table:
        f.unknown(ref_table, ("label", "reflectance", "geometries"), "reference")
        geoms = ref_table.get("geometries", [[0.0, 0.0, 10.0]])
        if (not isinstance(geoms, list) or not geoms
                or not all(isinstance(g, list) and len(g) == 3 for g in geoms)):
            raise f.fail("reference.geometries", "a list of [theta_i, phi_i, view] triples [deg]", geoms)
        reference = Reference(
            label=f.string(ref_table, "label", "reference"),
            reflectance=f.number(ref_table, "reflectance", "reference", None, 0.0, 1.0),
            geometries=tuple(tuple(float(x) for x in g) for g in geoms),
        )

    raw_blocks = data.get("block")
    if not isinstance(raw_blocks, list) or not raw_blocks:
        raise ProtocolError(f"{source}: field 'block': expected at least one [[block]] table with theta_i and view")
    blocks = []
    for k, raw in enumerate(raw_blocks):
        where = f"block[{k}]"
        if not isinstance(raw, Mapping):
            raise f.fail(where, "a table", raw)
        f.unknown(raw, ("name", "theta_i", "phi_i", "view", "repeats", "geometries"), where)
        if "geometries" in raw:
            blocks.extend(_geometry_blocks(f, raw, where))
            continue
        theta_values = raw.get("theta_i")
        thetas = f.angles(theta_values, f"{where}.theta_i") if isinstance(theta_values, (list, dict)) else (
            f.number(raw, "theta_i", where, None, 0.0, 90.0, "deg"),)
        for t in thetas:
            if not 0.0 <= t <= 90.0:
                raise f.fail(f"{where}.theta_i", "angles in [0, 90] [deg]", t)
        phi = f.number(raw, "phi_i", where, 0.0, -360.0, 360.0, "deg")
        if "view" not in raw:
            raise f.fail(f"{where}.view", "a list of signed camera angles [deg] or {start, stop, step} (required)", show_got=False)
        views = f.angles(raw["view"], f"{where}.view")
        repeats = f.integer(raw, "repeats", where, 1, low=1)
        label = raw.get("name", None)
        if label is not None and not isinstance(label, str):
            raise f.fail(f"{where}.name", "a string", label)
        for t in thetas:
            default = f"theta_i={t:g}" + (f", phi_i={phi:g}" if phi else "")
            blocks.append(Block(name=label or default, theta_i=t, phi_i=phi, views=views, repeats=repeats))
    return Protocol(
        name=name, sample=sample, description=description, metadata=dict(metadata), rig=rig,
        exposure=exposure, darks=darks, blocks=tuple(blocks), reference=reference,
        source=source, text=text,
    )


def _geometry_blocks(f: _Fields, raw: Mapping, where: str) -> list[Block]:
    """Blocks from explicit sample-frame geometries, grouped by lamp direction.

    ``geometries`` lists [theta_i, phi_i, theta_r, phi_r] in degrees (sample frame); each is
    mapped to rig coordinates with :func:`rig_coordinates` (relative azimuth preserved), and
    points sharing a lamp direction form one block so the lamp moves once per direction.
    """
    for key in ("theta_i", "phi_i", "view"):
        if key in raw:
            raise f.fail(f"{where}.{key}", "no theta_i/phi_i/view in a block that lists geometries", raw[key])
    geoms = raw["geometries"]
    name = f"{where}.geometries"
    if (not isinstance(geoms, list) or not geoms or not all(
            isinstance(g, list) and len(g) == 4
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in g) for g in geoms)):
        raise f.fail(name, "a non-empty list of [theta_i, phi_i, theta_r, phi_r] quadruples [deg]", geoms if not isinstance(geoms, list) else geoms[:3])
    array = np.array(geoms, dtype=float)
    bad = (array[:, 0] < 0) | (array[:, 0] > 90) | (array[:, 2] < 0) | (array[:, 2] > 90)
    if bad.any():
        k = int(np.argmax(bad))
        raise f.fail(f"{name}[{k}]", "polar angles theta_i, theta_r in [0, 90] [deg]", geoms[k])
    repeats = f.integer(raw, "repeats", where, 1, low=1)
    label = raw.get("name", "geometries")
    if not isinstance(label, str):
        raise f.fail(f"{where}.name", "a string", label)
    ti, lamp_phi, view = rig_coordinates(array[:, 0], array[:, 1], array[:, 2], array[:, 3])
    lamp = np.round(np.stack([ti, lamp_phi], axis=1), 6)
    groups: dict[tuple[float, float], list[float]] = {}
    for (t, p), v in zip(map(tuple, lamp), view):
        groups.setdefault((float(t), float(p)), []).append(float(v))
    return [
        Block(name=f"{label} theta_i={t:g} phi_i={p:g}", theta_i=t, phi_i=p, views=tuple(sorted(vs)), repeats=repeats)
        for (t, p), vs in sorted(groups.items())
    ]


def load(path: str | Path) -> Protocol:
    """Read and validate a protocol file.

    Parameters
    ----------
    path : str or Path
        TOML protocol file (format: docs/protocols.md).

    Returns
    -------
    Protocol

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ProtocolError
        If the file is not valid TOML or a field is missing, unknown or out of range; the
        message names the file, the field and what was expected.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"protocol file not found: {path}") from None
    except UnicodeDecodeError:
        raise ProtocolError(f"{path}: not a UTF-8 text file") from None
    return loads(text, source=str(path))


# --------------------------------------------------------------------------- planning
@dataclass(frozen=True)
class PlannedPoint:
    """One measurement point in rig coordinates and in sample coordinates [deg].

    ``theta_r``/``phi_r`` and ``theta_i``/``phi_i`` are the viewing and lamp directions in
    the sample frame whose azimuth 0 is the camera's swing plane on the positive side.
    """

    index: int  # position in the full expansion of the protocol, refused points included
    block: str
    repeat: int
    theta_i: float
    phi_i: float
    view: float

    @property
    def theta_r(self) -> float:
        return abs(self.view)

    @property
    def phi_r(self) -> float:
        return 0.0 if self.view >= 0 else 180.0

    @property
    def key(self) -> tuple:
        """Identity of the point within its protocol (used to resume without duplicates)."""
        return (self.block, self.repeat, self.theta_i, self.phi_i, self.view)


@dataclass(frozen=True)
class Refusal:
    """A point the rig would refuse, and why."""

    point: PlannedPoint
    reason: str


@dataclass(frozen=True)
class Plan:
    """The ordered points of a protocol, what is refused, and the estimated time."""

    protocol: Protocol
    points: tuple[PlannedPoint, ...]
    refused: tuple[Refusal, ...]
    dark_frames: int
    estimated_seconds: float
    moves: dict = field(default_factory=dict)

    def summary(self) -> str:
        """Human-readable dry-run report (what ``gonio plan`` prints)."""
        lines = [
            f"protocol {self.protocol.name!r} ({self.protocol.source}), sample {self.protocol.sample!r}",
            f"  blocks: {len(self.protocol.blocks)}",
            f"  points to measure: {len(self.points)}",
            f"  points refused: {len(self.refused)}",
            f"  dark frames: {self.dark_frames}",
            f"  exposure: {self.protocol.exposure.mode}",
            f"  estimated instrument time: {_duration(self.estimated_seconds)} (lamp warm-up not included)",
        ]
        if self.protocol.reference:
            lines.append(f"  reference standard: {self.protocol.reference.label} "
                         f"({len(self.protocol.reference.geometries)} geometries)")
        if self.refused:
            lines.append("refused points (not measured):")
            for r in self.refused:
                p = r.point
                lines.append(f"  [{p.block}] theta_i={p.theta_i:g} phi_i={p.phi_i:g} view={p.view:g}: {r.reason}")
        return "\n".join(lines)


def _duration(seconds: float) -> str:
    minutes, sec = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours:d}:{minutes:02d}:{sec:02d} (h:mm:ss)"


def camera_lamp_separation(theta_i: float, phi_i: float, view: float) -> float:
    """Angle between the camera and the lamp directions [deg] for rig coordinates."""
    return float(angle_between(theta_i, phi_i, abs(view), 0.0 if view >= 0 else 180.0))


def refusal_reason(theta_i: float, phi_i: float, view: float, rig: RigLimits) -> str | None:
    """Why the rig would refuse this geometry, or None if it can measure it."""
    lo, hi = rig.camera_range
    if not lo <= view <= hi:
        return f"camera angle {view:g} deg outside travel [{lo:g}, {hi:g}] deg"
    lo, hi = rig.lamp_theta_range
    if not lo <= theta_i <= hi:
        return f"lamp theta_i {theta_i:g} deg outside travel [{lo:g}, {hi:g}] deg"
    lo, hi = rig.lamp_phi_range
    if not lo <= phi_i <= hi:
        return f"lamp phi_i {phi_i:g} deg outside travel [{lo:g}, {hi:g}] deg"
    separation = camera_lamp_separation(theta_i, phi_i, view)
    # Exactly the minimum is allowed; 1e-6 deg absorbs the rounding of the angle
    # computation (a 5 deg step lands on 4.9999999999 deg otherwise).
    if separation < rig.min_separation - SEPARATION_TOLERANCE:
        return (f"camera and lamp only {separation:.2f} deg apart "
                f"(minimum separation {rig.min_separation:g} deg)")
    return None


def move_time(distance: float, velocity: float, acceleration: float) -> float:
    """Time of a trapezoidal (or triangular) velocity-profile move [s]."""
    distance = abs(distance)
    if distance == 0.0:
        return 0.0
    ramp = velocity**2 / acceleration  # distance spent accelerating + decelerating
    if distance <= ramp:
        return 2.0 * math.sqrt(distance / acceleration)
    return distance / velocity + velocity / acceleration


def _exposure_estimate(exposure: Exposure, rig: RigLimits) -> float:
    """Estimated camera time per point [s]: frames x (exposure + readout), auto adds tries."""
    if exposure.mode == "hdr":
        per_frame = sum(exposure.brackets) + rig.readout_time * len(exposure.brackets)
    elif exposure.mode == "auto":
        per_frame = 3 * (exposure.time + rig.readout_time)  # typical: two trial frames + one
    else:
        per_frame = exposure.time + rig.readout_time
    return exposure.frames * per_frame


def plan(protocol: Protocol) -> Plan:
    """Expand a protocol into measurement points, refusals and a time estimate.

    Points are visited block by block (the lamp moves once per block), camera angles in
    the order given, each block's sweep repeated ``repeats`` times.  The time estimate adds
    stage moves (trapezoidal profile; axes move one after another, as a conservative
    bound), settling, exposures and dark frames.
    """
    rig = protocol.rig
    points, refused = [], []
    index = 0
    position = (0.0, 0.0, 0.0)  # camera view, lamp theta, lamp phi after homing
    seconds = 0.0
    moves = {"camera": 0.0, "lamp_theta": 0.0, "lamp_phi": 0.0}
    per_point = _exposure_estimate(protocol.exposure, rig) + rig.settle_time
    for block in protocol.blocks:
        for repeat in range(block.repeats):
            for view in block.views:
                point = PlannedPoint(index, block.name, repeat, block.theta_i, block.phi_i, view)
                index += 1
                reason = refusal_reason(block.theta_i, block.phi_i, view, rig)
                if reason:
                    refused.append(Refusal(point, reason))
                    continue
                target = (view, block.theta_i, block.phi_i)
                for axis, a, b in zip(moves, position, target):
                    moves[axis] += abs(b - a)
                    seconds += move_time(b - a, rig.velocity, rig.acceleration)
                position = target
                seconds += per_point
                points.append(point)
    darks = (1 if protocol.darks.at_start else 0) + (
        (len(points) - 1) // protocol.darks.every if protocol.darks.every and points else 0
    )
    dark_time = protocol.exposure.max_time if protocol.exposure.mode == "auto" else protocol.exposure.time
    seconds += darks * (min(dark_time, 1.0) + rig.readout_time)
    if protocol.reference:
        seconds += len(protocol.reference.geometries) * (per_point + 2 * move_time(90.0, rig.velocity, rig.acceleration))
    return Plan(protocol, tuple(points), tuple(refused), darks, seconds, moves)


def rig_coordinates(theta_i, phi_i, theta_r, phi_r) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Map sample-frame directions [deg] to rig coordinates (theta_i, phi_i, view).

    The camera goes to the positive side of its swing plane at |view| = theta_r, and the lamp
    azimuth is taken relative to the viewing azimuth, so that phi_r - phi_i is preserved
    (exact for isotropic samples; the rig has no sample rotation).  Returns lamp polar
    angle, lamp azimuth relative to the swing plane in (-180, 180], and the signed view.
    """
    theta_i, phi_i, theta_r, phi_r = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    lamp_phi = azimuth_difference(phi_r, phi_i)  # phi_i - phi_r, wrapped
    return theta_i.copy(), lamp_phi, theta_r.copy()

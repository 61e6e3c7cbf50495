"""Sweep protocols: the TOML files users write to script a measurement, and their plans.

A protocol names the sample, the rig's limits, how to expose, how often to take dark
frames, an optional reference-standard measurement, optional lamp-stability checks, and
blocks of lamp directions each with the camera angles to visit.  :func:`load` reads and
validates a file (every error names the file, the field and what was expected);
:func:`plan` turns a protocol into the ordered list of measurement points, lists every
point the rig would refuse (travel limits, camera/lamp separation) with its reason, and
estimates the instrument time.

The rig (Oren & Nayar 1995, section 5, Fig 15; our rig motorises the lamp) has three axes:
the camera swings in one plane (signed camera angle ``view``: the camera sits at polar
angle |view| on the azimuth-0 side of that plane for view >= 0, on the azimuth-180 side
for view < 0), the lamp polar angle ``theta_i``, and the lamp azimuth ``phi_i`` measured
about the sample normal from the camera's swing plane.  With phi_i = 0 the camera sweeps
the plane of incidence and ``view`` is the signed viewing angle of DESIGN.md (positive on
the source side).  The rig has no sample-rotation stage, so it realises any pair of
directions up to a common rotation about the normal: for isotropic samples (all the
papers' models) that is every geometry.

Every number in a protocol must be finite, and the size of a plan is bounded
(:data:`MAX_PLANNED_POINTS`, :data:`MAX_REPEATS`, :data:`MAX_FRAMES`,
:data:`MAX_HDR_BRACKETS`) and checked arithmetically before anything is expanded, so a
mistyped file fails at once with one message instead of exhausting time or memory.

The file format is documented in docs/protocols.md.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import stat
import sys
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

from drivers.acceptance import GeometryRule
from drivers.emulator.stage_firmware import DEFAULT_AXES
from drivers.rig_geometry import angular_separation, axis_targets, camera_direction, plan_moves

from .geometry import azimuth_difference

__all__ = [
    "ProtocolError",
    "extended",
    "RigLimits",
    "Exposure",
    "Darks",
    "Reference",
    "Checks",
    "Mountings",
    "Block",
    "Protocol",
    "PlannedPoint",
    "Refusal",
    "Plan",
    "load",
    "loads",
    "plan",
    "rig_coordinates",
    "MAX_PLANNED_POINTS",
    "MAX_REPEATS",
    "MAX_FRAMES",
    "MAX_HDR_BRACKETS",
]

FORMAT_VERSION = 1

#: Most measurement points a protocol may plan (blocks x theta_i x view x repeats, refused
#: points included), checked arithmetically before the plan is expanded.
MAX_PLANNED_POINTS = 200_000
#: Most repeats of one block's sweep.
MAX_REPEATS = 10_000
#: Most frames averaged per point (``exposure.frames``) or per check (``checks.frames``).
MAX_FRAMES = 100
#: Fewest frames of a lamp-stability check (its scatter measures the flicker).
MIN_CHECK_FRAMES = 2
#: Most mountings of the sample in one protocol (``[sample] mountings``).
MAX_MOUNTINGS = 100
#: Most exposure times of an HDR bracket series.
MAX_HDR_BRACKETS = 16
#: Longest exposure the camera takes [s]: the upper end of an HDR bracket.
MAX_EXPOSURE_SECONDS = 60.0
#: Most angles one ``{start, stop, step}`` range expands to.
MAX_RANGE_ANGLES = 100_000
#: Largest protocol file read [bytes] (a protocol is a few kB; this stops a device or a
#: data file given by mistake from filling the memory).
MAX_FILE_BYTES = 10_000_000
#: Stage speed and acceleration the time estimate uses when the protocol leaves the
#: controller's settings [deg/s, deg/s^2]: the slowest axis's (the camera swing), for bounds.
DEFAULT_VELOCITY = 10.0
DEFAULT_ACCELERATION = 20.0
#: Speed and acceleration of each axis (1 camera swing, 2 lamp polar angle, 3 lamp
#: azimuth) the time estimate of a move uses when the protocol leaves the controller's
#: settings [deg/s, deg/s^2]: the emulated ESP300's defaults (10/20, 15/30, 20/40).
DEFAULT_AXIS_MOTION = {axis.number: (axis.velocity, axis.acceleration) for axis in DEFAULT_AXES}
#: Relative standard uncertainties of a reference standard are at most this [-].
MAX_REFERENCE_UNCERTAINTY = 0.5


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
    velocity : float or None
        Stage slew speed [deg/s] programmed into every stage axis; None leaves the
        controller's setting (the time estimate then assumes 10 deg/s).
    acceleration : float or None
        Stage acceleration [deg/s^2] programmed into every stage axis; None leaves the
        controller's setting (the time estimate then assumes 20 deg/s^2).
    settle_time : float
        Wait after each move before exposing [s].
    readout_time : float
        CCD readout time per frame [s].
    lamp_solid_angle, camera_solid_angle : float
        Apertures of the lamp and of the camera's pupil seen from the sample [sr]
        (Oren & Nayar 1995, section 5: 0.003 and 0.0009); fits of the recording average
        the model over them (gonio.instrument).
    remount_time : float
        Time the operator needs to take the sample out and put it back, or to swap it
        for the reference standard [s] (the time estimate; the emulated operator takes it).
    """

    camera_range: tuple[float, float] = (-90.0, 90.0)
    lamp_theta_range: tuple[float, float] = (0.0, 90.0)
    lamp_phi_range: tuple[float, float] = (-180.0, 180.0)
    min_separation: float = 5.0
    velocity: float | None = None
    acceleration: float | None = None
    settle_time: float = 0.2
    readout_time: float = 0.1
    lamp_solid_angle: float = 0.003
    camera_solid_angle: float = 0.0009
    remount_time: float = 60.0

    @property
    def geometry_rule(self) -> GeometryRule:
        """The rule the rig applies to a geometry (:mod:`drivers.acceptance`) with these
        travel limits and separation and the emulated camera's optics."""
        return GeometryRule(self.camera_range, self.lamp_theta_range, self.lamp_phi_range, self.min_separation)

    @property
    def estimate_velocity(self) -> float:
        """Stage speed the time estimate uses [deg/s]: ``velocity``, else 10 deg/s."""
        return DEFAULT_VELOCITY if self.velocity is None else self.velocity

    def axis_motion(self, axis: int) -> tuple[float, float]:
        """Speed [deg/s] and acceleration [deg/s^2] the estimate of a move of stage ``axis``
        uses: ``velocity`` and ``acceleration`` when the protocol programs them, else that
        axis's default (:data:`DEFAULT_AXIS_MOTION`)."""
        velocity, acceleration = DEFAULT_AXIS_MOTION[axis]
        return (velocity if self.velocity is None else self.velocity,
                acceleration if self.acceleration is None else self.acceleration)

    @property
    def estimate_acceleration(self) -> float:
        """Stage acceleration the time estimate uses [deg/s^2]: ``acceleration``, else 20."""
        return DEFAULT_ACCELERATION if self.acceleration is None else self.acceleration


@dataclass(frozen=True)
class Exposure:
    """Exposure policy.

    Attributes
    ----------
    mode : str
        ``"auto"`` (adjust the exposure until the ROI mean sits near ``target_fraction`` of
        full scale with no saturated pixel, starting from ``time``), ``"fixed"`` (always
        ``time``) or ``"hdr"`` (one frame per time in ``brackets``, combined from the
        unsaturated ones).
    time : float
        The fixed exposure time, or the first guess of the automatic exposure [s]
        (1e-6 to 60).
    brackets : tuple of float
        HDR exposure times [s], each in (0, 60], at most 16 (mode ``"hdr"`` only).
    target_fraction : float
        The automatic exposure's aim: the ROI mean as a fraction of full scale [-]
        (0.05 to 0.95); passed to the rig.
    max_time : float
        The longest automatic exposure [s] (1e-6 to 600); passed to the rig.
    frames : int
        Frames averaged per point (1 to 100).
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

    Attributes
    ----------
    label : str
        What the standard is.
    reflectance : float
        Its certified (Lambertian) albedo [-], in [0, 1].
    geometries : tuple of (float, float, float)
        (theta_i, phi_i, view) where it is measured [deg].
    reflectance_uncertainty : float
        Relative standard uncertainty of the certified reflectance [-], in [0, 0.5].
    angular_uncertainty : float
        Relative standard uncertainty from the standard's departure from Lambertian at
        the measured geometries [-], in [0, 0.5].
    """

    label: str
    reflectance: float
    geometries: tuple[tuple[float, float, float], ...]
    reflectance_uncertainty: float = 0.0
    angular_uncertainty: float = 0.0


@dataclass(frozen=True)
class Checks:
    """Lamp-stability check measurements, for rigs without a lamp monitor.

    The check geometry on the sample is re-measured with ``frames`` exposures before the
    first sample point, after every ``every`` measured sample points, at the end of the
    sample points (before the reference standard, if any) and after the reference block.
    The reduction interpolates the lamp drift between checks and measures the flicker from
    their scatter.

    Attributes
    ----------
    every : int
        Measured sample points between checks; 0 = no checks at all.
    geometry : (float, float, float) or None
        (theta_i, phi_i, view) of the check [deg]; None = the first planned point the
        plan does not refuse.
    frames : int
        Exposures per check (2 to 100).
    """

    every: int = 0
    geometry: tuple[float, float, float] | None = None
    frames: int = 5


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
class Mountings:
    """How often, and how, the sample is put into its holder (``[sample]`` table).

    Every sample point of the protocol is measured once in each mounting: the operator
    takes the sample out and puts it back between them (rotated as ``rotations`` say), so
    that the recording shows how much the values change with the sample's seating and
    with the part of its texture the camera sees, which the reduction then states
    (docs/acquisition.md, "Mountings").

    Attributes
    ----------
    count : int
        Mountings (1: the sample is mounted once).
    rotations : tuple of (float or None)
        Rotation of the sample about its normal in each mounting [deg]; None where the
        protocol leaves it to the operator.
    spin : bool
        The holder spins the sample about its normal during every exposure.

    Examples
    --------
    >>> Mountings(4).rotations
    (None, None, None, None)
    """

    count: int = 1
    rotations: tuple = ()
    spin: bool = False

    def __post_init__(self) -> None:
        if not self.rotations:
            object.__setattr__(self, "rotations", (None,) * self.count)
        if len(self.rotations) != self.count:
            raise ValueError(f"{len(self.rotations)} rotations for {self.count} mountings")

    @property
    def declared(self) -> bool:
        """Whether the protocol asks for anything beyond one plain mounting."""
        return self.count > 1 or self.spin or any(r is not None for r in self.rotations)


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
    checks: Checks = Checks()
    source: str = "<string>"
    text: str = ""
    #: The sample spec the emulated rig puts on the stage (``[sample] emulated``), or None.
    emulated: str | None = None
    #: Mountings of the sample (``[sample] mountings``, ``rotations``, ``spin``).
    mountings: Mountings = Mountings()


# --------------------------------------------------------------------------- field reading
def _finite(value: Any) -> float | None:
    """``value`` as a float if it is a finite number (not a bool), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the float range
        return None
    return number if math.isfinite(number) else None


def _interval(low: float, high: float, low_open: bool = False) -> str:
    """``[low, high]``, ``(low, high]``, ``[low, inf)`` ... as text."""
    left = f"({low:g}" if low_open or low == -math.inf else f"[{low:g}"
    right = f"{high:g})" if high == math.inf else f"{high:g}]"
    return f"{left}, {right}"


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


class _Fields:
    """Reads typed fields from a TOML table, raising errors that name file and field.

    Parameters
    ----------
    source : str
        The file (or ``<string>``) named in every message.
    """

    def __init__(self, source: str):
        self.source = source

    def fail(self, field_name: str, expected: str, got: Any = None, *, show_got: bool = True) -> ProtocolError:
        """The error for ``field_name``: what was expected and (optionally) what was found."""
        tail = f", got {_shown(got)}" if show_got else ""
        return ProtocolError(f"{self.source}: field '{field_name}': expected {expected}{tail}")

    def table(self, data: Mapping, key: str, where: str, required: bool = False) -> Mapping:
        """The sub-table ``key`` (empty when absent and not required)."""
        value = data.get(key, None)
        if value is None:
            if required:
                raise self.fail(_join(where, key), "a table", show_got=False)
            return {}
        if not isinstance(value, Mapping):
            raise self.fail(_join(where, key), "a table", value)
        return value

    def unknown(self, data: Mapping, allowed: Iterable[str], where: str) -> None:
        """Refuse keys of ``data`` outside ``allowed`` (suggesting the nearest known one)."""
        allowed = set(allowed)
        for key in data:
            if key not in allowed:
                hint = difflib.get_close_matches(key, sorted(allowed), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise ProtocolError(
                    f"{self.source}: field '{_join(where, key)}' is not a known field{extra}; "
                    f"known fields here: {sorted(allowed)}"
                )

    def string(self, data: Mapping, key: str, where: str, default: str | None = None) -> str:
        """A non-empty one-line string (required unless ``default`` is given)."""
        value = data.get(key, default)
        if value is None:
            raise self.fail(_join(where, key), "a string (required)", show_got=False)
        if not isinstance(value, str) or not value.strip():
            raise self.fail(_join(where, key), "a non-empty string", value)
        return self.one_line(value, _join(where, key))

    def one_line(self, value: str, field_name: str) -> str:
        """``value``, refused if it holds a control character or a line or paragraph
        separator: names and labels end up in the recording's files and reports, one
        line each."""
        bad = next((c for c in value if unicodedata.category(c) in ("Cc", "Zl", "Zp") and c != "\t"), None)
        if bad is not None:
            raise self.fail(field_name, f"text on one line, without control characters (found U+{ord(bad):04X} "
                                        f"{unicodedata.name(bad, 'control character')})", value)
        return value

    def number(
        self, data: Mapping, key: str, where: str, default: float | None = None,
        low: float = -math.inf, high: float = math.inf, unit: str = "", low_open: bool = False,
    ) -> float:
        """A finite number in [low, high] (or (low, high] with ``low_open``)."""
        value = data.get(key, default)
        name = _join(where, key)
        if value is None:
            raise self.fail(name, f"a finite number{_unit(unit)} (required)", show_got=False)
        return self.bounded(value, name, low, high, unit, low_open)

    def optional_number(
        self, data: Mapping, key: str, where: str, low: float, high: float, unit: str, low_open: bool = False,
    ) -> float | None:
        """Like :meth:`number`, but None when the key is absent."""
        if key not in data:
            return None
        return self.bounded(data[key], _join(where, key), low, high, unit, low_open)

    def bounded(self, value: Any, name: str, low: float, high: float, unit: str = "", low_open: bool = False) -> float:
        """``value`` as a float, refused unless finite and within the interval."""
        number = _finite(value)
        inside = number is not None and (low < number if low_open else low <= number) and number <= high
        if not inside:
            span = "" if (low, high) == (-math.inf, math.inf) else f" in {_interval(low, high, low_open)}"
            raise self.fail(name, f"a finite number{span}{_unit(unit)}", value)
        return number

    def integer(
        self, data: Mapping, key: str, where: str, default: int, low: int = 0,
        high: int | None = None, limit: str = "",
    ) -> int:
        """An integer in [low, high]; ``limit`` names the protocol limit ``high`` is."""
        value = data.get(key, default)
        name = _join(where, key)
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            expected = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
            raise self.fail(name, expected, value)
        if high is not None and value > high:
            why = f" ({limit})" if limit else ""
            raise self.fail(name, f"an integer in [{low}, {high}]{why}", value)
        return int(value)

    def boolean(self, data: Mapping, key: str, where: str, default: bool) -> bool:
        """true or false."""
        value = data.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(_join(where, key), "true or false", value)
        return value

    def pair(
        self, data: Mapping, key: str, where: str, default: tuple[float, float], unit: str,
        low: float, high: float,
    ) -> tuple[float, float]:
        """[a, b] of finite numbers with low <= a <= b <= high."""
        value = data.get(key, list(default))
        name = _join(where, key)
        expected = f"[low, high] of finite numbers with low <= high, within {_interval(low, high)}{_unit(unit)}"
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(name, expected, value)
        numbers = [_finite(v) for v in value]
        if None in numbers or not low <= numbers[0] <= numbers[1] <= high:
            raise self.fail(name, expected, value)
        return numbers[0], numbers[1]

    def numbers(
        self, value: Any, name: str, low: float, high: float, unit: str, *,
        what: str = "angles", max_count: int = MAX_RANGE_ANGLES, limit: str = "", low_open: bool = False,
    ) -> tuple[float, ...]:
        """A list of finite numbers, or a range table {start, stop, step} (stop included).

        The count of a range is computed before it is expanded; every value must lie in
        [low, high] (or (low, high] with ``low_open``) [``unit``].
        """
        span = f"{_interval(low, high, low_open)}{_unit(unit)}"
        why = f" ({limit})" if limit else ""
        if isinstance(value, list):
            if not value:
                raise self.fail(name, f"a non-empty list of {what} {span} or {{start, stop, step}}", value)
            if len(value) > max_count:
                raise self.fail(name, f"at most {max_count} {what}{why}", _Said(f"{len(value)} values"))
            return tuple(self.bounded(v, f"{name}[{k}]", low, high, unit, low_open) for k, v in enumerate(value))
        if isinstance(value, Mapping):
            self.unknown(value, ("start", "stop", "step"), name)
            start = self.number(value, "start", name, low=low, high=high, unit=unit, low_open=low_open)
            stop = self.number(value, "stop", name, low=low, high=high, unit=unit, low_open=low_open)
            step = self.number(value, "step", name, low=1e-6, unit=unit)
            if stop < start:
                raise self.fail(name, "stop >= start", {"start": start, "stop": stop})
            count = math.floor((stop - start) / step + 1e-9) + 1
            if count > max_count:
                raise self.fail(name, f"at most {max_count} {what}{why}", _Said(f"{count} values"))
            values = tuple(round(start + k * step, 10) for k in range(count))
            return tuple(self.bounded(v, name, low, high, unit, low_open) for v in values)
        raise self.fail(name, f"a list of {what} {span} or a table {{start, stop, step}}", value)

    def rig_geometry(self, value: Any, name: str, view_limit: float) -> tuple[float, float, float]:
        """A [theta_i, phi_i, view] triple [deg]: finite, theta_i in [0, 90], phi_i in
        [-360, 360], view in [-view_limit, view_limit]."""
        if not isinstance(value, list) or len(value) != 3:
            raise self.fail(name, "a [theta_i, phi_i, view] triple of numbers [deg]", value)
        theta_i = self.bounded(value[0], f"{name}[0] (theta_i)", 0.0, 90.0, "deg")
        phi_i = self.bounded(value[1], f"{name}[1] (phi_i)", -360.0, 360.0, "deg")
        view = self.bounded(value[2], f"{name}[2] (view)", -view_limit, view_limit, "deg")
        return theta_i, phi_i, view

    def finite_tree(self, value: Any, name: str) -> None:
        """Refuse NaN or infinite numbers anywhere in a free-form value (metadata)."""
        if isinstance(value, Mapping):
            for key, item in value.items():
                self.finite_tree(item, _join(name, str(key)))
        elif isinstance(value, list):
            for k, item in enumerate(value):
                self.finite_tree(item, f"{name}[{k}]")
        elif isinstance(value, float) and not math.isfinite(value):
            raise self.fail(name, "a finite number", value)


class _Said(str):
    """A description of what was found, shown without quotes in a message."""

    def __repr__(self) -> str:
        return str(self)


def _shown(value: Any, limit: int = 120) -> str:
    """``repr(value)`` cut to ``limit`` characters (a field may hold a huge list)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --------------------------------------------------------------------------- sections
_TOP_LEVEL = ("protocol", "sample", "rig", "exposure", "darks", "reference", "checks", "block")


def loads(text: str, source: str = "<string>") -> Protocol:
    """Parse and validate protocol TOML text (see :func:`load`).

    Parameters
    ----------
    text : str
        The TOML text.
    source : str
        Name used in error messages (the file).

    Returns
    -------
    Protocol

    Raises
    ------
    ProtocolError
        Invalid TOML, or a field missing, unknown, not finite, out of range or beyond a
        protocol limit; the message names the file, the field and what was expected.
    """
    data = _parse_toml(text, source)
    f = _Fields(source)
    f.unknown(data, _TOP_LEVEL, "")
    name, description = _read_header(f, data)
    sample, metadata, emulated, mountings = _read_sample(f, data)
    rig = _read_rig(f, f.table(data, "rig", ""))
    exposure = _read_exposure(f, f.table(data, "exposure", ""))
    darks = _read_darks(f, f.table(data, "darks", ""))
    reference = _read_reference(f, f.table(data, "reference", ""))
    checks = _read_checks(f, f.table(data, "checks", ""), rig)
    blocks = _read_blocks(f, data.get("block"))
    return Protocol(
        name=name, sample=sample, description=description, metadata=dict(metadata), rig=rig,
        exposure=exposure, darks=darks, blocks=tuple(blocks), reference=reference, checks=checks,
        source=source, text=text, emulated=emulated, mountings=mountings,
    )


def extended(protocol: Protocol, text: str) -> Protocol:
    r"""``protocol`` with ``text`` (``[[block]]`` sections and comments) appended.

    A recording that grows while it is measured (an adaptive run, :mod:`gonio.adaptive`)
    keeps every point it has: the blocks so far, the reference standard, the exposure and
    every other setting stay as they are, and the new blocks' points come after the old
    ones in the plan. A protocol with several mountings of the sample is not extended (its
    new points would be measured in every mounting, each a remount).

    >>> base = loads('[protocol]\nname = "x"\n[sample]\nlabel = "s"\n[[block]]\ntheta_i = 30\nview = [0]\n')
    >>> [b.views for b in extended(base, '[[block]]\nname = "more"\ntheta_i = 30\nview = [10, 20]\n').blocks]
    [(0.0,), (10.0, 20.0)]

    Raises
    ------
    ValueError
        ``text`` changes more than the blocks, or the protocol mounts the sample more than once.
    """
    if protocol.mountings.count > 1:
        raise ValueError(f"{protocol.source}: the protocol mounts the sample {protocol.mountings.count} times; only "
                         "a protocol with one mounting is extended")
    grown = loads(protocol.text.rstrip("\n") + "\n" + text, source=protocol.source)
    same = dataclasses.replace(grown, blocks=protocol.blocks, text=protocol.text)
    if same != protocol or grown.blocks[:len(protocol.blocks)] != protocol.blocks:
        raise ValueError(f"{protocol.source}: the appended text changes more than the blocks; expected [[block]] "
                         "sections only")
    return grown


def _parse_toml(text: str, source: str) -> dict:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ProtocolError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:
        raise ProtocolError(f"{source}: not valid TOML: arrays or tables nested too deeply") from None


def _read_header(f: _Fields, data: Mapping) -> tuple[str, str]:
    head = f.table(data, "protocol", "", required=True)
    f.unknown(head, ("name", "description", "format_version"), "protocol")
    version = f.integer(head, "format_version", "protocol", FORMAT_VERSION, low=1)
    if version != FORMAT_VERSION:
        raise f.fail("protocol.format_version", f"{FORMAT_VERSION} (the version this gonio reads)", version)
    name = f.string(head, "name", "protocol")
    description = head.get("description", "")
    if not isinstance(description, str):
        raise f.fail("protocol.description", "a string", description)
    return name, description


def _read_sample(f: _Fields, data: Mapping) -> tuple[str, Mapping, str | None, Mountings]:
    table = f.table(data, "sample", "", required=True)
    f.unknown(table, ("label", "metadata", "emulated", "mountings", "rotations", "spin"), "sample")
    label = f.string(table, "label", "sample")
    metadata = f.table(table, "metadata", "sample")
    f.finite_tree(metadata, "sample.metadata")
    emulated = None
    if "emulated" in table:
        emulated = f.string(table, "emulated", "sample").strip()
        _check_emulated_sample(f, emulated)
    return label, metadata, emulated, _read_mountings(f, table)


def _read_mountings(f: _Fields, table: Mapping) -> Mountings:
    """``[sample] mountings``, ``rotations`` and ``spin``: a count, or rotations (one mounting
    each), or both when they agree."""
    spin = f.boolean(table, "spin", "sample", False)
    count = f.integer(table, "mountings", "sample", 1, low=1, high=MAX_MOUNTINGS,
                      limit="the limit on mountings") if "mountings" in table else None
    if "rotations" not in table:
        return Mountings(count or 1, spin=spin)
    value = table["rotations"]
    if not isinstance(value, list) or not value:
        raise f.fail("sample.rotations", "a non-empty list of rotations of the sample about its normal, "
                     "one per mounting, each in [-360, 360] [deg]", value)
    rotations = f.numbers(value, "sample.rotations", -360.0, 360.0, "deg", what="rotations", max_count=MAX_MOUNTINGS,
                          limit="the limit on mountings")
    if count is not None and count != len(rotations):
        raise f.fail("sample.mountings", f"the number of sample.rotations ({len(rotations)}), or no mountings field",
                     count)
    return Mountings(len(rotations), tuple(rotations), spin)


def _check_emulated_sample(f: _Fields, spec: str) -> None:
    """Refuse a ``[sample] emulated`` that the emulator's sample parser refuses.

    The rules of ``--sample`` (:func:`gonio.sample_specs.check_sample_spec`, imported here
    so that this module stays light); a CUReT spec is checked for its form only, its data
    are read when a rig is emulated.
    """
    from .sample_specs import SPEC_SYNTAX, check_sample_spec

    try:
        check_sample_spec(spec)
    except ValueError as error:
        raise f.fail("sample.emulated", f"a sample spec ({SPEC_SYNTAX}); {error}", show_got=False) from None


def _read_rig(f: _Fields, table: Mapping) -> RigLimits:
    f.unknown(table, RigLimits.__dataclass_fields__.keys(), "rig")
    base = RigLimits()
    return RigLimits(
        camera_range=f.pair(table, "camera_range", "rig", base.camera_range, "deg", -180.0, 180.0),
        lamp_theta_range=f.pair(table, "lamp_theta_range", "rig", base.lamp_theta_range, "deg", 0.0, 90.0),
        lamp_phi_range=f.pair(table, "lamp_phi_range", "rig", base.lamp_phi_range, "deg", -360.0, 360.0),
        min_separation=f.number(table, "min_separation", "rig", base.min_separation, 0.0, 90.0, "deg"),
        velocity=f.optional_number(table, "velocity", "rig", 0.0, math.inf, "deg/s", low_open=True),
        acceleration=f.optional_number(table, "acceleration", "rig", 0.0, math.inf, "deg/s^2", low_open=True),
        settle_time=f.number(table, "settle_time", "rig", base.settle_time, 0.0, unit="s"),
        readout_time=f.number(table, "readout_time", "rig", base.readout_time, 0.0, unit="s"),
        lamp_solid_angle=f.number(table, "lamp_solid_angle", "rig", base.lamp_solid_angle, 0.0, 1.0, "sr"),
        camera_solid_angle=f.number(table, "camera_solid_angle", "rig", base.camera_solid_angle, 0.0, 1.0, "sr"),
        remount_time=f.number(table, "remount_time", "rig", base.remount_time, 0.0, 86400.0, "s"),
    )


def _read_exposure(f: _Fields, table: Mapping) -> Exposure:
    f.unknown(table, Exposure.__dataclass_fields__.keys(), "exposure")
    mode = table.get("mode", "auto")
    if mode not in ("auto", "fixed", "hdr"):
        raise f.fail("exposure.mode", "one of 'auto', 'fixed', 'hdr'", mode)
    brackets: tuple[float, ...] = ()
    if mode == "hdr":
        if "brackets" not in table:
            raise f.fail("exposure.brackets", "a list of exposure times [s] (required for mode 'hdr')", show_got=False)
        brackets = f.numbers(
            table["brackets"], "exposure.brackets", 0.0, MAX_EXPOSURE_SECONDS, "s", low_open=True,
            what="exposure times", max_count=MAX_HDR_BRACKETS,
            limit=f"the limit on HDR brackets; each within the camera's range (0, {MAX_EXPOSURE_SECONDS:g}] s",
        )
    elif "brackets" in table:
        raise f.fail("exposure.brackets", "no brackets unless mode = 'hdr'", table["brackets"])
    return Exposure(
        mode=mode,
        time=f.number(table, "time", "exposure", 0.02, 1e-6, MAX_EXPOSURE_SECONDS, "s"),
        brackets=brackets,
        target_fraction=f.number(table, "target_fraction", "exposure", 0.5, 0.05, 0.95),
        max_time=f.number(table, "max_time", "exposure", 5.0, 1e-6, 600.0, "s"),
        frames=f.integer(table, "frames", "exposure", 1, low=1, high=MAX_FRAMES, limit="the limit on frames per point"),
    )


def _read_darks(f: _Fields, table: Mapping) -> Darks:
    f.unknown(table, ("at_start", "every"), "darks")
    return Darks(
        at_start=f.boolean(table, "at_start", "darks", True),
        every=f.integer(table, "every", "darks", 20, low=0),
    )


def _read_reference(f: _Fields, table: Mapping) -> Reference | None:
    if not table:
        return None
    f.unknown(table, Reference.__dataclass_fields__.keys(), "reference")
    raw = table.get("geometries", [[0.0, 0.0, 10.0]])
    if not isinstance(raw, list) or not raw:
        raise f.fail("reference.geometries", "a non-empty list of [theta_i, phi_i, view] triples [deg]", raw)
    if len(raw) > MAX_PLANNED_POINTS:
        raise f.fail("reference.geometries", f"at most {MAX_PLANNED_POINTS} geometries (the limit on planned points)",
                     _Said(f"{len(raw)} geometries"))
    geometries = tuple(f.rig_geometry(g, f"reference.geometries[{k}]", 90.0) for k, g in enumerate(raw))
    return Reference(
        label=f.string(table, "label", "reference"),
        reflectance=f.number(table, "reflectance", "reference", None, 0.0, 1.0),
        geometries=geometries,
        reflectance_uncertainty=f.number(table, "reflectance_uncertainty", "reference", 0.0,
                                         0.0, MAX_REFERENCE_UNCERTAINTY),
        angular_uncertainty=f.number(table, "angular_uncertainty", "reference", 0.0, 0.0, MAX_REFERENCE_UNCERTAINTY),
    )


def _read_checks(f: _Fields, table: Mapping, rig: RigLimits) -> Checks:
    f.unknown(table, Checks.__dataclass_fields__.keys(), "checks")
    geometry = None
    if "geometry" in table:
        geometry = f.rig_geometry(table["geometry"], "checks.geometry", 180.0)
        reason = refusal_reason(*geometry, rig)
        if reason is not None:
            raise f.fail("checks.geometry", f"a geometry the rig can measure (the plan refuses it: {reason})",
                         table["geometry"])
    return Checks(
        every=f.integer(table, "every", "checks", 0, low=0),
        geometry=geometry,
        frames=f.integer(table, "frames", "checks", Checks.frames, low=MIN_CHECK_FRAMES, high=MAX_FRAMES,
                         limit="the limit on frames per check"),
    )


_BLOCK_FIELDS = ("name", "theta_i", "phi_i", "view", "repeats", "geometries")


def _read_blocks(f: _Fields, raw_blocks: Any) -> list[Block]:
    """Every ``[[block]]``, refusing a protocol that plans more than MAX_PLANNED_POINTS."""
    if not isinstance(raw_blocks, list) or not raw_blocks:
        raise ProtocolError(f"{f.source}: field 'block': expected at least one [[block]] table with theta_i and view")
    blocks: list[Block] = []
    planned = 0
    for k, raw in enumerate(raw_blocks):
        where = f"block[{k}]"
        if not isinstance(raw, Mapping):
            raise f.fail(where, "a table", raw)
        f.unknown(raw, _BLOCK_FIELDS, where)
        new = _geometry_blocks(f, raw, where) if "geometries" in raw else _sweep_blocks(f, raw, where)
        planned += sum(len(b.views) * b.repeats for b in new)
        if planned > MAX_PLANNED_POINTS:
            raise f.fail(where, f"at most {MAX_PLANNED_POINTS} planned points in total (the limit on blocks x "
                                "theta_i x view x repeats)", _Said(f"{planned} points up to this block"))
        blocks.extend(new)
    return blocks


def _block_name(f: _Fields, raw: Mapping, where: str, default: str | None) -> str | None:
    label = raw.get("name", default)
    if label is not None and not isinstance(label, str):
        raise f.fail(f"{where}.name", "a string", label)
    return label if label is None else f.one_line(label, f"{where}.name")


def _repeats(f: _Fields, raw: Mapping, where: str) -> int:
    return f.integer(raw, "repeats", where, 1, low=1, high=MAX_REPEATS, limit="the limit on repeats")


def _sweep_blocks(f: _Fields, raw: Mapping, where: str) -> list[Block]:
    """One block per lamp polar angle of a ``theta_i``/``phi_i``/``view`` table.

    The size (thetas x views x repeats) is checked before any block is made.
    """
    theta_value = raw.get("theta_i")
    if isinstance(theta_value, (list, Mapping)):
        thetas = f.numbers(theta_value, f"{where}.theta_i", 0.0, 90.0, "deg")
    else:
        thetas = (f.number(raw, "theta_i", where, None, 0.0, 90.0, "deg"),)
    phi = f.number(raw, "phi_i", where, 0.0, -360.0, 360.0, "deg")
    if "view" not in raw:
        raise f.fail(f"{where}.view", "a list of signed camera angles [deg] or {start, stop, step} (required)",
                     show_got=False)
    views = f.numbers(raw["view"], f"{where}.view", -180.0, 180.0, "deg")
    repeats = _repeats(f, raw, where)
    planned = len(thetas) * len(views) * repeats
    if planned > MAX_PLANNED_POINTS:
        raise f.fail(where, f"at most {MAX_PLANNED_POINTS} planned points in total (the limit on blocks x "
                            "theta_i x view x repeats)",
                     _Said(f"{len(thetas)} theta_i x {len(views)} views x {repeats} repeats = {planned} points"))
    label = _block_name(f, raw, where, None)
    blocks = []
    for t in thetas:
        default = f"theta_i={t:g}" + (f", phi_i={phi:g}" if phi else "")
        blocks.append(Block(name=label or default, theta_i=t, phi_i=phi, views=views, repeats=repeats))
    return blocks


def _geometry_blocks(f: _Fields, raw: Mapping, where: str) -> list[Block]:
    """Blocks from explicit sample-frame geometries, grouped by lamp direction.

    ``geometries`` lists [theta_i, phi_i, theta_r, phi_r] in degrees (sample frame); each is
    mapped to rig coordinates with :func:`rig_coordinates` (relative azimuth preserved), and
    points sharing a lamp direction form one block so the lamp moves once per direction.
    """
    for key in ("theta_i", "phi_i", "view"):
        if key in raw:
            raise f.fail(f"{where}.{key}", "no theta_i/phi_i/view in a block that lists geometries", raw[key])
    array = _sample_geometries(f, raw["geometries"], f"{where}.geometries")
    repeats = _repeats(f, raw, where)
    if len(array) * repeats > MAX_PLANNED_POINTS:
        raise f.fail(where, f"at most {MAX_PLANNED_POINTS} planned points in total (the limit on geometries x "
                            "repeats)", _Said(f"{len(array)} geometries x {repeats} repeats"))
    label = _block_name(f, raw, where, "geometries")
    ti, lamp_phi, view = rig_coordinates(array[:, 0], array[:, 1], array[:, 2], array[:, 3])
    lamp = np.round(np.stack([ti, lamp_phi], axis=1), 6)
    groups: dict[tuple[float, float], list[float]] = {}
    for (t, p), v in zip(map(tuple, lamp), view):
        groups.setdefault((float(t), float(p)), []).append(float(v))
    return [
        Block(name=f"{label} theta_i={t:g} phi_i={p:g}", theta_i=t, phi_i=p, views=tuple(sorted(vs)), repeats=repeats)
        for (t, p), vs in sorted(groups.items())
    ]


def _sample_geometries(f: _Fields, geoms: Any, name: str) -> np.ndarray:
    """[theta_i, phi_i, theta_r, phi_r] rows [deg]: finite, polar angles in [0, 90],
    azimuths in [-360, 360]."""
    expected = "a non-empty list of [theta_i, phi_i, theta_r, phi_r] quadruples [deg]"
    if not isinstance(geoms, list) or not geoms:
        raise f.fail(name, expected, geoms)
    if len(geoms) > MAX_PLANNED_POINTS:
        raise f.fail(name, f"at most {MAX_PLANNED_POINTS} geometries (the limit on planned points)",
                     _Said(f"{len(geoms)} geometries"))
    rows = []
    for k, g in enumerate(geoms):
        if not isinstance(g, list) or len(g) != 4:
            raise f.fail(f"{name}[{k}]", "a [theta_i, phi_i, theta_r, phi_r] quadruple of numbers [deg]", g)
        rows.append((
            f.bounded(g[0], f"{name}[{k}][0] (theta_i)", 0.0, 90.0, "deg"),
            f.bounded(g[1], f"{name}[{k}][1] (phi_i)", -360.0, 360.0, "deg"),
            f.bounded(g[2], f"{name}[{k}][2] (theta_r)", 0.0, 90.0, "deg"),
            f.bounded(g[3], f"{name}[{k}][3] (phi_r)", -360.0, 360.0, "deg"),
        ))
    return np.array(rows, dtype=float)


def load(path: str | Path) -> Protocol:
    """Read and validate a protocol file.

    Parameters
    ----------
    path : str or Path
        TOML protocol file (format: docs/protocols.md), at most 10 MB.

    Returns
    -------
    Protocol

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ProtocolError
        If the path cannot be read (a directory, a device, a symlink loop, no permission),
        the file is not UTF-8 TOML, or a field is missing, unknown, not finite, out of range
        or beyond a protocol limit; the message names the file, the field and what was
        expected.
    """
    path = Path(path)
    return loads(_read_text(path), source=str(path))


def _read_text(path: Path) -> str:
    """The UTF-8 text of a regular file of at most MAX_FILE_BYTES (stat first: a FIFO or a
    device is never opened)."""
    try:
        status = path.stat()
        if stat.S_ISDIR(status.st_mode):
            raise ProtocolError(f"{path}: cannot read the protocol file: it is a directory, expected a TOML file")
        if not stat.S_ISREG(status.st_mode):
            raise ProtocolError(f"{path}: cannot read the protocol file: not a regular file, expected a TOML file")
        with open(path, "rb") as handle:
            data = handle.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise FileNotFoundError(f"protocol file not found: {path}") from None
    except OSError as error:
        raise ProtocolError(f"{path}: cannot read the protocol file: {error.strerror or error}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ProtocolError(f"{path}: cannot read the protocol file: larger than {MAX_FILE_BYTES // 1_000_000} MB, "
                            "expected a TOML protocol of a few kB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError(f"{path}: not a UTF-8 text file") from None


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
    mounting: int = 0  # the sample's mounting (0-based) the point is measured in

    @property
    def theta_r(self) -> float:
        return abs(self.view)

    @property
    def phi_r(self) -> float:
        return 0.0 if self.view >= 0 else 180.0

    @property
    def key(self) -> tuple:
        """Identity of the point within its protocol (used to resume without duplicates)."""
        return (self.block, self.repeat, self.theta_i, self.phi_i, self.view, self.mounting)


@dataclass(frozen=True)
class Refusal:
    """A point the rig would refuse, and why."""

    point: PlannedPoint
    reason: str


@dataclass(frozen=True)
class Plan:
    """The ordered points of a protocol, what is refused, and the estimated time.

    Attributes
    ----------
    protocol : Protocol
    points : tuple of PlannedPoint
        The points to measure, in order.
    refused : tuple of Refusal
        The points the rig would refuse, with the reasons.
    dark_frames : int
        Dark frames the run takes.
    estimated_seconds : float
        Estimated instrument time [s] (lamp warm-up not included).
    moves : dict
        Total travel per axis [deg].
    checks : int
        Lamp-stability check measurements the run makes (see :class:`Checks`).
    """

    protocol: Protocol
    points: tuple[PlannedPoint, ...]
    refused: tuple[Refusal, ...]
    dark_frames: int
    estimated_seconds: float
    moves: dict = field(default_factory=dict)
    checks: int = 0

    @property
    def check_geometry(self) -> tuple[float, float, float] | None:
        """(theta_i, phi_i, view) of the lamp-stability checks [deg], or None without checks.

        The protocol's ``checks.geometry``, else the first point the plan measures.
        """
        if self.checks == 0:
            return None
        if self.protocol.checks.geometry is not None:
            return self.protocol.checks.geometry
        first = self.points[0]
        return first.theta_i, first.phi_i, first.view

    def summary(self) -> str:
        """Human-readable dry-run report (what ``gonio plan`` prints)."""
        lines = [
            f"protocol {self.protocol.name!r} ({self.protocol.source}), sample {self.protocol.sample!r}",
            f"  blocks: {len(self.protocol.blocks)}",
            f"  points to measure: {len(self.points)}",
            f"  points refused: {len(self.refused)}",
            f"  dark frames: {self.dark_frames}",
            f"  lamp-stability checks: {self._checks_text()}",
            f"  exposure: {self.protocol.exposure.mode}",
            f"  estimated instrument time: {_duration(self.estimated_seconds)} (lamp warm-up not included)",
        ]
        mountings = self.protocol.mountings
        if mountings.declared:
            rotations = ", ".join("operator's choice" if r is None else f"{r:g} deg" for r in mountings.rotations)
            lines.insert(3, f"  mountings of the sample: {mountings.count} (rotations: {rotations})"
                            + ("; spinning during exposures" if mountings.spin else ""))
        if self.protocol.reference:
            lines.append(f"  reference standard: {self.protocol.reference.label} "
                         f"({len(self.protocol.reference.geometries)} geometries)")
        if self.refused:
            lines.append("refused points (not measured):")
            for r in self.refused:
                p = r.point
                lines.append(f"  [{p.block}] theta_i={p.theta_i:g} phi_i={p.phi_i:g} view={p.view:g}: {r.reason}")
        return "\n".join(lines)

    def _checks_text(self) -> str:
        if self.checks == 0:
            return "0"
        theta_i, phi_i, view = self.check_geometry
        checks = self.protocol.checks
        return (f"{self.checks} (every {checks.every} points, {checks.frames} frames each, at "
                f"theta_i={theta_i:g} phi_i={phi_i:g} view={view:g})")


def _duration(seconds: float) -> str:
    minutes, sec = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours:d}:{minutes:02d}:{sec:02d} (h:mm:ss)"


def camera_lamp_separation(theta_i: float, phi_i: float, view: float) -> float:
    """Angle between the camera and the lamp directions [deg] for rig coordinates (the
    rig's own geometry, :func:`drivers.rig_geometry.angular_separation`)."""
    return float(angular_separation(theta_i, phi_i, *camera_direction(view)))


def refusal_reason(theta_i: float, phi_i: float, view: float, rig: RigLimits) -> str | None:
    """Why the rig would refuse the geometry ``(theta_i, phi_i, view)`` [deg], or None: the
    rig's own rule with ``rig``'s limits (:meth:`drivers.acceptance.GeometryRule.refusal`)."""
    return rig.geometry_rule.refusal(theta_i, phi_i, view)


def refusal_reasons(theta_i: float, phi_i: float, views: Sequence[float], rig: RigLimits) -> list[str | None]:
    """:func:`refusal_reason` for every camera angle of one lamp direction (one array pass).

    The rig's own rule (:meth:`drivers.acceptance.GeometryRule.refusals`, the rule
    :meth:`drivers.rig.Rig.check_geometry` applies): travel limits, the camera-lamp
    separation, and a radiance window that fits on the sample's image (the emulated
    camera's optics).

    Parameters
    ----------
    theta_i, phi_i : float
        Lamp polar angle and azimuth [deg].
    views : sequence of float
        Signed camera angles [deg].
    rig : RigLimits

    Returns
    -------
    list of str or None
        Per view, the reason the rig refuses it, or None.
    """
    return rig.geometry_rule.refusals(theta_i, phi_i, views)


def move_time(distance: float, velocity: float, acceleration: float) -> float:
    """Time of a trapezoidal (or triangular) velocity-profile move [s].

    Parameters
    ----------
    distance : float
        Travel [deg] (sign ignored).
    velocity : float
        Slew speed [deg/s].
    acceleration : float
        Acceleration and deceleration [deg/s^2].
    """
    distance = abs(distance)
    if distance == 0.0:
        return 0.0
    ramp = velocity**2 / acceleration  # distance spent accelerating + decelerating
    if distance <= ramp:
        return 2.0 * math.sqrt(distance / acceleration)
    return distance / velocity + velocity / acceleration


def _frame_seconds(exposure: Exposure, rig: RigLimits) -> float:
    """Camera time of one exposure [s]: exposure + readout (HDR: the whole bracket series)."""
    if exposure.mode == "hdr":
        return sum(exposure.brackets) + rig.readout_time * len(exposure.brackets)
    return exposure.time + rig.readout_time


#: Exposure the automatic exposure settles on at normal incidence [s], for a white
#: diffuse sample under the emulated 300 W lamp (0.026-0.038 s measured); it grows as
#: ``1 / cos(theta_i)`` with the irradiance (0.12-0.26 s at theta_i = 75 deg). A darker
#: sample takes longer.
AUTO_EXPOSURE_AT_NORMAL = 0.03


def _exposure_estimate(exposure: Exposure, rig: RigLimits, theta_i: float = 0.0) -> float:
    """Estimated camera time per point at lamp polar angle ``theta_i`` [deg] [s]: frames x
    exposure; an automatic exposure starts from ``exposure.time`` and takes two more frames
    at the exposure it settles on (:data:`AUTO_EXPOSURE_AT_NORMAL` / cos theta_i, within
    ``exposure.time`` and ``exposure.max_time``)."""
    if exposure.mode != "auto":
        return exposure.frames * _frame_seconds(exposure, rig)
    settled = AUTO_EXPOSURE_AT_NORMAL / max(math.cos(math.radians(theta_i)), 1e-3)
    settled = min(max(settled, exposure.time), exposure.max_time)
    return exposure.frames * (exposure.time + 2 * settled + 3 * rig.readout_time)


def planned_point_count(protocol: Protocol) -> int:
    """Points the plan of ``protocol`` expands to, refused included (no expansion)."""
    return protocol.mountings.count * sum(len(block.views) * block.repeats for block in protocol.blocks)


#: Camera time of the texture image and monitor series taken in every mounting [s]: an
#: automatic exposure at the characterisation geometry, two frames of the window read out
#: at the camera's 115200 baud (138 x 138 pixels of 2 bytes each: 3.3 s per frame) and 48
#: exposures of the monitor series.
TEXTURE_IMAGE_SECONDS = 16.0


def mounting_seconds(protocol: Protocol) -> float:
    """Instrument time of the mountings [s]: the operator's remounts between them
    (``rig.remount_time`` each) and one texture image per mounting (:data:`TEXTURE_IMAGE_SECONDS`
    and, but for the first, taken where the camera's characterisation left the stage, a
    move there of at most 90 deg)."""
    rig = protocol.rig
    long_move = move_time(90.0, rig.estimate_velocity, rig.estimate_acceleration)
    count = protocol.mountings.count
    return (count - 1) * (rig.remount_time + long_move) + count * (rig.settle_time + TEXTURE_IMAGE_SECONDS)


def check_count(checks: Checks, measured_points: int, reference_measured: bool) -> int:
    """Lamp-stability checks of a run.

    Parameters
    ----------
    checks : Checks
        The protocol's ``[checks]``.
    measured_points : int
        Sample points the plan measures (refused ones excluded).
    reference_measured : bool
        Whether a reference block follows the sample points.

    Returns
    -------
    int
        0 without checks (``every == 0``) or without a measured point; else one before the
        first point, one after every ``every`` points before the last, one at the end and one
        after the reference block: ``2 + (n - 1) // every (+ 1)``.
    """
    if checks.every == 0 or measured_points == 0:
        return 0
    return 2 + (measured_points - 1) // checks.every + (1 if reference_measured else 0)


def plan(protocol: Protocol) -> Plan:
    """Expand a protocol into measurement points, refusals and a time estimate.

    Points are visited mounting by mounting (``[sample] mountings``), in each block by
    block (the lamp moves once per block), camera angles in the order given, each block's
    sweep repeated ``repeats`` times.  The time estimate is everything the run spends
    after the lamp's warm-up (:func:`run_seconds`): the camera's characterisation, the
    stage moves (trapezoidal profile; the axes of one move command travel together, as
    the driver sends them), settling, exposures, dark frames, the remounts and the
    texture image of every mounting (:func:`mounting_seconds`), the reference standard
    (swapped in and out, each ``rig.remount_time``) and the lamp checks.

    Raises
    ------
    ProtocolError
        If the protocol plans more than :data:`MAX_PLANNED_POINTS` points (checked before
        anything is expanded).
    """
    total = planned_point_count(protocol)
    if total > MAX_PLANNED_POINTS:
        raise ProtocolError(f"{protocol.source}: field 'block': expected at most {MAX_PLANNED_POINTS} planned points "
                            f"in total (the limit on blocks x theta_i x view x repeats), got {total}")
    rig = protocol.rig
    points, refused, moves, seconds = _expand(protocol)
    darks = (1 if protocol.darks.at_start else 0) + (
        (len(points) - 1) // protocol.darks.every if protocol.darks.every and points else 0
    )
    dark_time = protocol.exposure.max_time if protocol.exposure.mode == "auto" else protocol.exposure.time
    seconds += darks * (min(dark_time, 1.0) + rig.readout_time)
    seconds += _reference_seconds(protocol, points)
    seconds += mounting_seconds(protocol)
    if points:
        seconds += CAMERA_CHARACTERISATION_SECONDS
    reference = protocol.reference
    reference_measured = reference is not None and any(refusal_reason(*g, rig) is None for g in reference.geometries)
    checks = check_count(protocol.checks, len(points), reference_measured)
    # a check: one move there (at most 90 deg, a bound), settling and its frames
    long_move = move_time(90.0, rig.estimate_velocity, rig.estimate_acceleration)
    seconds += checks * (long_move + rig.settle_time + protocol.checks.frames * _frame_seconds(protocol.exposure, rig))
    return Plan(protocol, tuple(points), tuple(refused), darks, seconds, moves, checks)


#: Instrument time of the camera's characterisation in a run [s]: the photon transfer at
#: the first point (an automatic exposure, then six exposures of two light and two dark
#: frames of the window, 24 frames read out at 115200 baud, about 3.4 s each) and the
#: linearity series after the last point (8 exposure levels up and down); measured on the
#: emulated rig at 83-86 s and 9-11 s (gonio.acquisition.characterise_camera,
#: characterise_linearity).
CAMERA_CHARACTERISATION_SECONDS = 95.0


def travel_seconds(start: tuple[float, float, float], end: tuple[float, float, float], rig: RigLimits) -> float:
    """Time the stage takes from geometry ``start`` to ``end`` [s], both ``(theta_i, phi_i,
    view)`` [deg]: the driver's move plan (:func:`drivers.rig_geometry.plan_moves`, one or
    two commands), the axes of one command travelling together at the estimate's speed.

    >>> travel_seconds((30, 0, -80), (45, 0, 80), RigLimits())   # the camera's 160 deg: 16 s + 0.5 s
    16.5
    >>> travel_seconds((30, 0, 40), (30, 90, 40), RigLimits())   # the lamp's azimuth: 4.5 s + 0.5 s
    5.0
    """
    current = axis_targets(*start)
    route = plan_moves(current, axis_targets(*end), rig.min_separation)
    stages = route.stages if route is not None else tuple(((a, t),) for a, t in axis_targets(*end).items())
    seconds = 0.0
    for stage in stages:
        seconds += max(move_time(target - current[axis], *rig.axis_motion(axis)) for axis, target in stage)
        current.update(dict(stage))
    return seconds


def _reference_seconds(protocol: Protocol, points: Sequence[PlannedPoint]) -> float:
    """The reference standard's part of the run [s]: swapped in after the last sample
    point and the sample back (two ``rig.remount_time``), each reference geometry
    measured in the order given."""
    reference, rig = protocol.reference, protocol.rig
    if reference is None:
        return 0.0
    def per_point(theta_i: float) -> float:
        return _exposure_estimate(protocol.exposure, rig, theta_i) + rig.settle_time

    last = points[-1] if points else None
    position = (last.theta_i, last.phi_i, last.view) if last else (0.0, 0.0, 0.0)
    seconds = 2 * rig.remount_time
    for geometry in reference.geometries:
        if refusal_reason(*geometry, rig) is None:
            seconds += travel_seconds(position, tuple(geometry), rig) + per_point(geometry[0])
            position = tuple(geometry)
    return seconds


def _expand(protocol: Protocol) -> tuple[list[PlannedPoint], list[Refusal], dict, float]:
    """Points, refusals, travel per axis [deg] and time of the sample points [s]."""
    rig = protocol.rig
    points, refused = [], []
    index = 0
    position: tuple[float, float, float] | None = None  # from the camera's characterisation point
    seconds = 0.0
    moves = {"camera": 0.0, "lamp_theta": 0.0, "lamp_phi": 0.0}
    per_point = {block.theta_i: _exposure_estimate(protocol.exposure, rig, block.theta_i) + rig.settle_time
                 for block in protocol.blocks}
    reasons = [refusal_reasons(block.theta_i, block.phi_i, block.views, rig) for block in protocol.blocks]
    for mounting in range(protocol.mountings.count):
        for block, block_reasons in zip(protocol.blocks, reasons):
            for repeat in range(block.repeats):
                for view, reason in zip(block.views, block_reasons):
                    point = PlannedPoint(index, block.name, repeat, block.theta_i, block.phi_i, view, mounting)
                    index += 1
                    if reason:
                        refused.append(Refusal(point, reason))
                        continue
                    target = (block.theta_i, block.phi_i, view)
                    position = position or target
                    for axis, a, b in zip(("lamp_theta", "lamp_phi", "camera"), position, target):
                        moves[axis] += abs(b - a)
                    seconds += travel_seconds(position, target, rig)
                    position = target
                    seconds += per_point[block.theta_i]
                    points.append(point)
    return points, refused, moves, seconds


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

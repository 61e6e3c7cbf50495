"""Departures of the emulated rig from the ideal: misalignment, stray light, non-linearity,
beam profile, and the sample as labs meet it (texture, wedge, remounting, the lamp monitor's
view of the beam).

A real gonioreflectometer is never perfect.  By default the emulated rig of
:class:`drivers.emulator.rig.EmulatedRig` is ideal (every switch here is 0: the stage reads
back exactly where the sample geometry is); :class:`Systematics` switches each of the
departures below on with its own magnitude, and :func:`realism` builds them from a preset
(``ideal``, ``lab``) with optional overrides, e.g. ``lab:stray_light=0``. docs/emulator.md,
"Systematic errors" and "The sample as labs meet it", justifies the ``lab`` magnitudes.

- **Axis zero offsets** (``view_offset``, ``theta_i_offset``, ``phi_i_offset`` [deg]): the
  stage reads back ``x``, the true angle of the axis is ``x + offset``.
- **Holder tilt** (``tilt_x``, ``tilt_y`` [deg]): the holder's face, and with it whatever is
  mounted, has its normal tipped toward +x (in the camera's swing plane) and toward +y
  (along the swing axis).  Both errors act through
  :func:`drivers.rig_geometry.misaligned_angles`, the function gonio's fits use for their
  alignment parameters.
- **Stray light** (``stray_light`` [-]): an additive radiance over the whole image,
  proportional to the lamp's output and independent of the geometry (light of the lamp
  scattered by the room and the rig into the camera, and veiling glare in its lens):
  ``L_stray = stray_light x E_0 / pi``, i.e. ``stray_light`` times the radiance of a white
  Lambertian sample at normal incidence.  Dark frames (shutter closed) do not see it.
- **Camera non-linearity** near full scale (``nonlinearity`` [-]): the digital signal
  above the dark offset, ``s = K x electrons``, comes out as
  ``s (1 - nonlinearity (s / s_fs)^2)`` with ``s_fs`` the ADC's range above the offset: a
  relative deficit of ``nonlinearity`` at full scale that vanishes at low signal as
  ``s^2`` (:func:`nonlinear_signal`).
- **Beam non-uniformity** (``beam_falloff`` [-]): the lamp's irradiance across its beam
  falls off quadratically with the distance ``r`` from the beam's axis,
  ``E(r) = E_0 (1 - beam_falloff (r / 25.4 mm)^2)`` (:func:`beam_profile`), the axis passing
  through the sample's centre.  The camera's window covers the same central area of the
  sample at every view (Oren & Nayar 1995, section 5), but the beam's footprint on the
  sample stretches by ``1 / cos(theta_i)`` along the lamp's azimuth, so the irradiance
  averaged over the window changes with the lamp direction (and, through the window's
  rounding to whole pixels, slightly with the view).
- **Sample texture** (``texture_albedo`` [-], ``texture_slope`` [deg], ``texture_length``
  [mm]): the sample's albedo and mesoscale slope vary over its surface as seeded Gaussian
  random fields of that rms and correlation length (:mod:`drivers.emulator.texture`); the
  camera's window averages them.
- **Sample wedge** (``wedge`` [deg]): the sample's face is not parallel to its back; the
  tilt this adds turns with the sample when it is mounted at another rotation.
- **Remounting** (``mount_tilt`` [deg]): each mounting seats the sample with another tilt,
  ``N(0, mount_tilt)`` toward +x and +y, and within the holder's play
  (:data:`drivers.emulator.texture.MOUNT_PLAY_MM`).
- **Lamp monitor mismatch** (``monitor_mismatch`` [-]): the irradiance on the sample
  fluctuates from exposure to exposure by this relative rms beyond what the lamp monitor
  sees (the monitor looks at the filament from another direction than the sample does).

References
----------
E. Molloy, P. Saunders, A. Koo, "Effects of rotation errors on goniometric measurements",
Metrologia 59(2), 2022.  European Machine Vision Association, EMVA Standard 1288 release
3.1 (2016), section 6.6 (linearity).  H. Li, K. E. Torrance, "Validation of the
gonioreflectometer", Cornell Program of Computer Graphics report PCG-03-2 (2003): stray
light, detector linearity and the illuminated footprint as tests of a gonioreflectometer.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

__all__ = ["Systematics", "PRESETS", "LAB_SPREAD_DEG", "LAB_FIXED", "LAB_SEED_STREAM", "ANGULAR", "SAMPLE",
           "SCALES", "realism", "lab_systematics", "nonlinear_signal", "beam_profile", "BEAM_RADIUS_MM"]

#: The angular (alignment) errors, in :func:`drivers.rig_geometry.misaligned_angles` order.
ANGULAR = ("view_offset", "theta_i_offset", "phi_i_offset", "tilt_x", "tilt_y")
#: The departures that belong to the sample and its mounting (drivers.emulator.texture).
SAMPLE = ("texture_albedo", "texture_slope", "wedge", "mount_tilt", "monitor_mismatch")
#: Fields that set a scale, not a magnitude: they do not make a rig less than ideal.
SCALES = ("texture_length",)
#: Distance from the beam axis at which ``beam_falloff`` is the irradiance deficit [mm]:
#: half the 2-inch sample's side.
BEAM_RADIUS_MM = 25.4
#: Standard deviation of the ``lab`` preset's seeded Gaussian draw of each angular error
#: [deg] (docs/emulator.md, "Systematic errors", justifies each).
LAB_SPREAD_DEG = {"view_offset": 0.1, "theta_i_offset": 0.2, "phi_i_offset": 0.3, "tilt_x": 0.2, "tilt_y": 0.2}
#: The ``lab`` preset's fixed magnitudes of the other errors (same section, and "The sample
#: as labs meet it"): fractions [-], except ``texture_slope``, ``wedge`` and ``mount_tilt``
#: [deg] and ``texture_length`` [mm].
LAB_FIXED = {"stray_light": 2e-3, "nonlinearity": 5e-3, "beam_falloff": 0.02,
             "texture_albedo": 0.03, "texture_slope": 0.3, "texture_length": 1.0, "wedge": 0.1,
             "mount_tilt": 0.05, "monitor_mismatch": 5e-4}
#: Index of the ``lab`` preset's random stream among the children of the rig's seed (the
#: rig itself uses children 0 to 7, so drawing the misalignment changes nothing else).
LAB_SEED_STREAM = 8
#: Largest magnitude accepted for an angular error [deg] and for the others [-]: beyond
#: these the "rig" is not misaligned but mis-built, and the emulator refuses it.
_ANGULAR_LIMIT_DEG = 10.0
_RELATIVE_LIMIT = 0.5
#: Accepted range of each field that is neither angular nor a fraction (unit in the name).
_RANGES = {"texture_slope": (0.0, 10.0, "deg"), "wedge": (0.0, _ANGULAR_LIMIT_DEG, "deg"),
           "mount_tilt": (0.0, _ANGULAR_LIMIT_DEG, "deg"), "texture_length": (0.3, 20.0, "mm")}


@dataclass(frozen=True)
class Systematics:
    """Magnitudes of the emulated rig's departures from the ideal (module docstring); 0 = ideal.

    Attributes
    ----------
    view_offset, theta_i_offset, phi_i_offset : float
        Zero offsets of axes 1, 2, 3 [deg]: true angle = readback + offset.
    tilt_x, tilt_y : float
        Tilt of the holder's normal toward +x and +y [deg].
    stray_light : float
        Stray radiance as a fraction of ``E_0 / pi`` [-] (>= 0).
    nonlinearity : float
        Relative signal deficit at the ADC's full scale [-] (>= 0).
    beam_falloff : float
        Relative irradiance deficit at 25.4 mm from the beam's axis [-] (>= 0).
    texture_albedo : float
        Relative rms of the sample's local albedo [-] (>= 0).
    texture_slope : float
        Rms of each component of the sample's mesoscale slope [deg], 0 to 10.
    texture_length : float
        Correlation length of the texture [mm], 0.3 to 20 (a scale: it does not make the
        rig less than ideal).
    wedge : float
        Angle between the sample's face and its back [deg], 0 to 10 (its direction is
        drawn from the rig's seed).
    mount_tilt : float
        Rms of the tilt of each seating of the sample, toward +x and +y [deg], 0 to 10.
    monitor_mismatch : float
        Relative rms of the irradiance fluctuation per exposure that the lamp monitor does
        not see [-].

    Raises
    ------
    ValueError
        A value that is not a finite number, an angle beyond 10 deg, a negative or
        larger than 0.5 relative magnitude, or a field outside its range; the message
        names the field.

    Examples
    --------
    >>> Systematics(view_offset=0.1).is_ideal, Systematics().is_ideal, Systematics(texture_length=5.0).is_ideal
    (False, True, True)
    """

    view_offset: float = 0.0
    theta_i_offset: float = 0.0
    phi_i_offset: float = 0.0
    tilt_x: float = 0.0
    tilt_y: float = 0.0
    stray_light: float = 0.0
    nonlinearity: float = 0.0
    beam_falloff: float = 0.0
    texture_albedo: float = 0.0
    texture_slope: float = 0.0
    texture_length: float = 1.0
    wedge: float = 0.0
    mount_tilt: float = 0.0
    monitor_mismatch: float = 0.0

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"systematic error {field.name}={value!r}: expected a finite number")
            if field.name in ANGULAR:
                if abs(value) > _ANGULAR_LIMIT_DEG:
                    raise ValueError(f"systematic error {field.name}={value!r} deg: expected an angle within "
                                     f"+/-{_ANGULAR_LIMIT_DEG:g} deg")
            elif field.name in _RANGES:
                lo, hi, unit = _RANGES[field.name]
                if not lo <= value <= hi:
                    raise ValueError(f"systematic error {field.name}={value!r} {unit}: expected a value in "
                                     f"[{lo:g}, {hi:g}] {unit}")
            elif not 0.0 <= value <= _RELATIVE_LIMIT:
                raise ValueError(f"systematic error {field.name}={value!r}: expected a fraction in "
                                 f"[0, {_RELATIVE_LIMIT:g}]")
            object.__setattr__(self, field.name, float(value))

    @property
    def is_ideal(self) -> bool:
        """True when every magnitude is 0 (the ideal rig; a texture's length is a scale)."""
        return all(getattr(self, f.name) == 0.0 for f in fields(self) if f.name not in SCALES)

    @property
    def misaligned(self) -> bool:
        """True when an axis offset or the holder's tilt is not 0."""
        return any(getattr(self, name) != 0.0 for name in ANGULAR)

    @property
    def textured(self) -> bool:
        """True when the sample has an albedo or slope texture."""
        return self.texture_albedo > 0.0 or self.texture_slope > 0.0

    def alignment(self) -> dict[str, float]:
        """The angular errors as keywords of :func:`drivers.rig_geometry.misaligned_angles` [deg]."""
        return {name: getattr(self, name) for name in ANGULAR}

    def only(self, *names: str) -> "Systematics":
        """These errors with their magnitudes, every other one 0 (one systematic alone); the
        scales (``texture_length``) are kept.

        Examples
        --------
        >>> Systematics(tilt_x=0.2, stray_light=0.01).only("stray_light").stray_light
        0.01
        >>> Systematics(tilt_x=0.2, stray_light=0.01).only("stray_light").tilt_x
        0.0
        """
        known = [f.name for f in fields(self)]
        unknown = [n for n in names if n not in known]
        if unknown:
            raise ValueError(f"unknown systematic error {unknown[0]!r}; known: {known}")
        return Systematics(**{n: getattr(self, n) for n in (*names, *SCALES)})

    def to_dict(self) -> dict[str, float]:
        """Every magnitude by name (for recordings' metadata)."""
        return asdict(self)


def lab_systematics(seed: int) -> Systematics:
    """The ``lab`` preset of rig ``seed``: seeded misalignment, fixed other magnitudes.

    The five angular errors are drawn once per seed from normal distributions with the
    standard deviations :data:`LAB_SPREAD_DEG` (each seed is another alignment of the rig,
    as each set-up of a real one is); stray light, non-linearity, beam fall-off and the
    sample's texture, wedge, remounting and monitor mismatch take the fixed typical values
    :data:`LAB_FIXED` (properties of the equipment and of a careful lab's handling).

    Examples
    --------
    >>> lab_systematics(0) == lab_systematics(0), lab_systematics(0) == lab_systematics(1)
    (True, False)
    """
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(LAB_SEED_STREAM,)))
    drawn = {name: float(LAB_SPREAD_DEG[name] * rng.standard_normal()) for name in ANGULAR}
    return Systematics(**drawn, **LAB_FIXED)


#: Presets of :func:`realism`: name -> function of the rig's seed.
PRESETS = {"ideal": lambda seed: Systematics(), "lab": lab_systematics}


def realism(spec: str, seed: int = 0) -> Systematics:
    """The systematics of a realism spec ``PRESET[:name=value,...]``.

    Parameters
    ----------
    spec : str
        A preset of :data:`PRESETS` (``ideal``: all 0; ``lab``: typical magnitudes, see
        :func:`lab_systematics`), optionally followed by ``:`` and comma-separated
        overrides of single errors, e.g. ``lab:stray_light=0`` or
        ``ideal:view_offset=0.2,tilt_y=-0.1``.
    seed : int
        The rig's seed (the ``lab`` preset's draw of the misalignment).

    Raises
    ------
    ValueError
        Unknown preset or error name, or a value that is not a number in its range; the
        message names what was wrong and what was expected.

    Examples
    --------
    >>> realism("ideal:stray_light=0.001").stray_light
    0.001
    >>> realism("lab:nonlinearity=0", seed=3).nonlinearity
    0.0
    """
    text = str(spec).strip()
    name, _, overrides = text.partition(":")
    name = name.strip()
    if name not in PRESETS:
        raise ValueError(f"realism {spec!r}: unknown preset {name!r}; expected one of {sorted(PRESETS)}, "
                         "optionally with overrides, e.g. lab:stray_light=0")
    systematics = PRESETS[name](seed)
    known = [f.name for f in fields(Systematics)]
    changes: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in overrides.split(","))):
        key, eq, value = (s.strip() for s in item.partition("="))
        if not eq or key not in known:
            raise ValueError(f"realism {spec!r}: {item!r} is not NAME=VALUE with NAME one of {known}")
        try:
            changes[key] = float(value)
        except ValueError:
            raise ValueError(f"realism {spec!r}: {key}={value!r} is not a number") from None
    try:
        return replace(systematics, **changes)
    except ValueError as error:
        raise ValueError(f"realism {spec!r}: {error}") from None


def nonlinear_signal(signal: np.ndarray, nonlinearity: float, full_scale: float,
                     out: np.ndarray | None = None) -> np.ndarray:
    """The camera's response to a linear signal ``s`` [DN above the dark offset].

    ``s (1 - nonlinearity (s / full_scale)^2)``: a relative deficit growing with the
    square of the signal, ``nonlinearity`` at ``full_scale``, vanishing at low signal.
    It is monotonic below full scale for ``nonlinearity < 1/3``.  EMVA 1288 (release 3.1,
    section 6.6) states a camera's linearity error as the relative deviation of the mean
    signal from its straight line between 5 % and 95 % of saturation; for this curve
    (saturation at full scale, the line fitted as the standard's reference implementation
    fits it, by relative deviation) it spans -0.55 to +0.23 times ``nonlinearity``.

    Examples
    --------
    ``out`` (optional, e.g. ``signal`` itself) receives the result, as numpy's ``out``: a
    frame's worth of temporaries fewer for the emulated camera.

    >>> float(nonlinear_signal(np.array(1000.0), 0.01, 4000.0))
    999.375
    """
    signal = np.asarray(signal, float)
    if nonlinearity == 0.0:
        if out is None:
            return signal
        out[...] = signal
        return out
    factor = signal / full_scale
    factor *= factor  # (signal / full_scale)^2, in place for an array
    factor *= nonlinearity
    factor = np.subtract(1.0, factor, out=factor if isinstance(factor, np.ndarray) else None)
    return np.multiply(signal, factor, out=out)


def beam_profile(x_mm: np.ndarray, y_mm: np.ndarray, theta_i: float, phi_i: float, falloff: float,
                 radius_mm: float = BEAM_RADIUS_MM) -> np.ndarray:
    """Irradiance at sample points relative to the beam's axis, ``1 - falloff (r / radius)^2``.

    Parameters
    ----------
    x_mm, y_mm : array_like
        Points on the sample's surface [mm] (origin at its centre, where the beam's axis
        meets it); broadcast against each other.
    theta_i, phi_i : float
        Direction of the lamp in the sample's frame [deg].
    falloff : float
        Relative deficit at ``radius_mm`` from the beam's axis [-].
    radius_mm : float
        Reference distance [mm].

    Returns
    -------
    numpy.ndarray
        ``E / E_0`` [-], where ``r^2 = |p|^2 - (p . l)^2`` is the squared distance of the
        point ``p`` from the beam's axis along the lamp direction ``l``.  The irradiance
        on the surface is ``E cos(theta_i)``; the cosine stays in the BRDF's radiometry.

    Examples
    --------
    >>> round(float(beam_profile(25.4, 0.0, 0.0, 0.0, 0.02)), 6)    # normal incidence, edge
    0.98
    >>> round(float(beam_profile(25.4, 0.0, 60.0, 0.0, 0.02)), 6)   # foreshortened: r = x cos(60)
    0.995
    """
    t, p = math.radians(theta_i), math.radians(phi_i)
    lx, ly = math.sin(t) * math.cos(p), math.sin(t) * math.sin(p)
    x, y = np.asarray(x_mm, float), np.asarray(y_mm, float)
    along = x * lx + y * ly
    r2 = x * x + y * y - along * along
    return 1.0 - falloff * r2 / radius_mm**2

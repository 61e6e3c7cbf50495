"""The emulated rig: world, instruments, transports and the control side channel for tests.

Examples
--------
>>> import numpy as np, serial
>>> lambert = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, 0.9 / np.pi)
>>> with EmulatedRig(lambert, seed=1, name="doc") as rig:
...     addresses = rig.start(pty=False)
...     port = serial.serial_for_url(rig.url("stage"), baudrate=19200, timeout=1)
...     _ = port.write(b"VE?\\r")
...     port.readline()
...     port.close()
b'ESP300 Version 3.08 09/09/02\\r\\n'
"""
from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import serial

from .camera_firmware import CameraFirmware
from .ccd import CCDParams, CCDSensor
from .clock import SimClock
from .holder import SampleHolder
from .lamp import Lamp, LampParams
from .lamp_firmware import LampFirmware
from .monitor import LampMonitor, MonitorParams
from .stage_firmware import DEFAULT_AXES, AxisConfig, Esp300Firmware
from .systematics import Systematics, beam_profile, nonlinear_signal
from .transports import DeviceChannel, PtyTransport, TcpTransport
from .world import (Optics, camera_angles, cone_averaged_reflectance, footprint_coverage, pixel_sample_coordinates,
                    separation_deg)
from ..rig_geometry import misaligned_angles

__all__ = ["EmulatedRig", "RigControl", "Scene", "TrueState", "find_rig", "BAUDRATES",
           "DEFAULT_LAMP_IRRADIANCE_W_M2"]

#: Line speeds of the instruments [bit/s] (docs/protocol.md).
BAUDRATES = {"stage": 19200, "camera": 115200, "lamp": 9600}

#: In-band irradiance of the warm lamp at rated voltage on a surface facing it [W/m^2].
#: Chosen so that a white Lambertian sample at normal incidence and view gives about
#: 2000 DN (mid-range of the 12-bit ADC) in 25 ms at gain 1 (see docs/emulator.md).
DEFAULT_LAMP_IRRADIANCE_W_M2 = 0.057

_RIGS: "weakref.WeakValueDictionary[str, EmulatedRig]" = weakref.WeakValueDictionary()
_RIGS_LOCK = threading.Lock()
#: Pixel patterns (:meth:`Scene.pixel_pattern`, 2 MB each) kept: a point's frames at one position.
_PATTERN_CACHE = 4

Brdf = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def find_rig(name: str) -> "EmulatedRig | None":
    """The started rig registered under ``name`` in this process, or None."""
    with _RIGS_LOCK:
        return _RIGS.get(name)


@dataclass(frozen=True)
class TrueState:
    """Ground truth of the simulated world at one instant (side channel).

    Attributes
    ----------
    time_s : float
        Simulated time [s].
    positions_deg : tuple of float
        True axis positions (a1, a2, a3) [deg].
    theta_i, phi_i, theta_r, phi_r : float
        Lamp and camera directions in the sample's frame [deg] (with the rig's
        misalignment, :class:`~drivers.emulator.systematics.Systematics`).
    lamp_output : float
        Lamp output relative to a warm lamp at rated voltage [-] (no flicker).
    irradiance_w_m2 : float
        In-band irradiance the lamp gives on a surface facing it [W/m^2].
    radiance_w_m2_sr : float
        Sample radiance toward the camera, averaged over the lamp and camera cones
        [W/(m^2 sr)].
    reflectance_factor : float
        ``<f cos theta_i>`` over the cones [1/sr] (radiance / irradiance).
    moving : tuple of bool
        Whether each axis is moving.
    stray_radiance_w_m2_sr : float
        Stray radiance added over the whole image [W/(m^2 sr)] (0 without stray light).
    """

    time_s: float
    positions_deg: tuple[float, float, float]
    theta_i: float
    phi_i: float
    theta_r: float
    phi_r: float
    lamp_output: float
    irradiance_w_m2: float
    radiance_w_m2_sr: float
    reflectance_factor: float
    moving: tuple[bool, bool, bool]
    stray_radiance_w_m2_sr: float = 0.0


class Scene:
    """What the camera sees: the sample lit by the lamp, imaged through the optics.

    Parameters
    ----------
    brdf : callable
        Sample BRDF ``brdf(theta_i, phi_i, theta_r, phi_r)`` [1/sr], degrees, broadcasting.
    optics : Optics
        Rig layout.
    lamp : Lamp
        The lamp (its output at the exposure time).
    stage : Esp300Firmware
        The motion controller (true axis positions).
    lamp_irradiance_w_m2 : float
        In-band irradiance of the warm lamp at rated voltage on a surface facing it [W/m^2].
    rng : numpy.random.Generator
        Lamp flicker source.
    systematics : Systematics, optional
        The rig's systematic errors that act on the scene: misalignment (the true
        directions), stray light and the beam profile (default: none).
    holder : SampleHolder, optional
        The sample holder: the mounted sample's texture, wedge and seating and the lamp
        monitor's mismatch (default: a holder with the sample of ``systematics``, seed 0).
    """

    def __init__(self, brdf: Brdf, optics: Optics, lamp: Lamp, stage: Esp300Firmware,
                 lamp_irradiance_w_m2: float, rng: np.random.Generator,
                 systematics: Systematics | None = None, holder: SampleHolder | None = None) -> None:
        self.systematics = systematics or Systematics()
        self.holder = holder or SampleHolder(self.systematics, 0, optics)
        self.brdf = brdf
        self.optics = optics
        self.lamp = lamp
        self.stage = stage
        self.lamp_irradiance_w_m2 = lamp_irradiance_w_m2
        self.rng = rng
        self._reflectance_cache: dict[tuple[float, float, float], float] = {}
        self._coverage_cache: dict[float, np.ndarray] = {}
        self._pattern_cache: dict[tuple[float, ...], np.ndarray] = {}

    def forget(self) -> None:
        """Clear what was cached of the mounted object (after a sample change or a remount)."""
        self._reflectance_cache.clear()
        self._pattern_cache.clear()

    def angles(self, positions: tuple[float, ...]) -> tuple[float, float, float, float]:
        """(theta_i, phi_i, theta_r, phi_r) [deg] in the sample's frame for axis positions
        (a1, a2, a3): the axes' own angles on an aligned rig, moved by the zero offsets and
        the sample tilt of a misaligned one (:func:`drivers.rig_geometry.misaligned_angles`)."""
        a1, a2, a3 = positions
        theta_r, phi_r = camera_angles(a1)
        extra_x, extra_y = self.holder.tilt()
        if not self.systematics.misaligned and extra_x == 0.0 and extra_y == 0.0:
            return float(a2), float(a3), theta_r, phi_r
        alignment = self.systematics.alignment()
        alignment["tilt_x"] += extra_x
        alignment["tilt_y"] += extra_y
        angles = misaligned_angles(a2, a3, theta_r, phi_r, **alignment)
        return tuple(float(a) for a in angles)  # type: ignore[return-value]

    def reflectance_factor(self, positions: tuple[float, ...]) -> float:
        """``<f cos theta_i>`` over the lamp and camera cones at these positions [1/sr]."""
        key = tuple(float(p) for p in positions)
        value = self._reflectance_cache.get(key)
        if value is None:
            ti, pi_, tr, pr = self.angles(key)
            value = cone_averaged_reflectance(self.brdf, ti, pi_, tr, pr, self.optics.lamp_solid_angle_sr,
                                              self.optics.camera_solid_angle_sr)
            if len(self._reflectance_cache) > 4096:
                self._reflectance_cache.clear()
            self._reflectance_cache[key] = value
        return value

    def coverage(self, theta_r: float) -> np.ndarray:
        """Cached :func:`~drivers.emulator.world.footprint_coverage`."""
        cov = self._coverage_cache.get(theta_r)
        if cov is None:
            if len(self._coverage_cache) > 64:
                self._coverage_cache.clear()
            cov = footprint_coverage(self.optics, theta_r)
            self._coverage_cache[theta_r] = cov
        return cov

    def radiance(self, positions: tuple[float, ...], lamp_output: float) -> float:
        """Sample radiance toward the camera on the beam's axis [W/(m^2 sr)]."""
        return self.lamp_irradiance_w_m2 * lamp_output * self.reflectance_factor(positions)

    def stray_radiance(self, lamp_output: float) -> float:
        """Stray radiance over the whole image [W/(m^2 sr)]: ``stray_light x E_0 / pi``."""
        return self.systematics.stray_light * self.lamp_irradiance_w_m2 * lamp_output / np.pi

    def beam_map(self, theta_r: float, theta_i: float, phi_i: float) -> np.ndarray:
        """Irradiance relative to the beam's axis at the sample point each pixel sees,
        shape (height, width) (:func:`~drivers.emulator.systematics.beam_profile`)."""
        x, y = pixel_sample_coordinates(self.optics, theta_r)
        return beam_profile(x[None, :], y[:, None], theta_i, phi_i, self.systematics.beam_falloff)

    def lamp_exposure(self, t_start: float, exposure_s: float) -> float:
        """Lamp output of one exposure: its mean over the exposure times one flicker factor [-].

        The camera's sample image and the lamp monitor both see this value (the monitor
        looks at the same lamp through a beam splitter), so one draw serves both.
        """
        return self.lamp.mean_output(t_start, t_start + exposure_s) * self.lamp.flicker_factor(exposure_s, self.rng)

    def photons(self, t_start: float, exposure_s: float, lamp: float) -> np.ndarray:
        """Mean photons per pixel of an exposure lit with lamp output ``lamp`` [photons].

        The geometry is taken at mid-exposure (true axis positions); shape (height, width).
        """
        positions = self.stage.true_positions(t_start + 0.5 * exposure_s)
        key = tuple(float(p) for p in positions)
        radiance = self.radiance(positions, lamp)
        if not np.isfinite(radiance) or radiance < 0:
            raise ValueError(f"the sample BRDF gave radiance {radiance!r} at axis positions "
                             f"{tuple(round(p, 3) for p in positions)}")
        per_radiance = self.optics.photon_rate_per_radiance() * exposure_s
        image = self.pixel_pattern(key) * (radiance * self.holder.beam_mismatch() * per_radiance)
        if self.systematics.stray_light:
            image += self.stray_radiance(lamp) * per_radiance
        return image

    def pixel_pattern(self, positions: tuple[float, ...]) -> np.ndarray:
        """Each pixel's radiance relative to the sample's on its axis at these true axis
        positions, shape (height, width) [-]: the sample's coverage of the pixel, times the
        beam profile and the texture where the rig has them.

        The same for every exposure at one position (a point's frames, its repeats), so the
        last few are kept (:meth:`forget` clears them).
        """
        pattern = self._pattern_cache.get(positions)
        if pattern is not None:
            return pattern
        angles = self.angles(positions)
        theta_i, phi_i, theta_r, _ = angles
        pattern = self.coverage(theta_r).copy()
        if self.systematics.beam_falloff and theta_r < 90.0:  # at 90 the sample has no image
            pattern *= self.beam_map(theta_r, theta_i, phi_i)
        if theta_r < 90.0:
            texture = self.holder.relative_image(self.brdf, angles, positions)
            if texture is not None:
                pattern *= texture
        if len(self._pattern_cache) >= _PATTERN_CACHE:
            self._pattern_cache.pop(next(iter(self._pattern_cache)))
        self._pattern_cache[positions] = pattern
        return pattern

    def __call__(self, t_start: float, exposure_s: float) -> np.ndarray:
        """Mean photons per pixel of an exposure [photons] (:meth:`photons` with a fresh
        :meth:`lamp_exposure`)."""
        return self.photons(t_start, exposure_s, self.lamp_exposure(t_start, exposure_s))


class RigControl:
    """Side channel of an :class:`EmulatedRig` for tests: faults, clock and ground truth.

    Nothing here is reachable over the serial lines.
    """

    def __init__(self, rig: "EmulatedRig") -> None:
        self._rig = rig

    # -- clock ------------------------------------------------------------------------
    def now(self) -> float:
        """Simulated time [s]."""
        return self._rig.clock.now()

    def advance(self, seconds: float) -> None:
        """Let simulated time pass (event and wall modes: a jump; real-time mode: a sleep)."""
        self._rig.clock.advance(seconds)

    def pause(self) -> None:
        """Stop the wall clock's part of simulated time (``wall`` mode; waits on the rig still jump)."""
        self._rig.clock.pause()

    def resume(self) -> None:
        """Let the wall clock's part of simulated time run again."""
        self._rig.clock.resume()

    def set_speed(self, speed: float) -> None:
        """Simulated seconds per wall second from now on (``wall`` and ``realtime`` modes)."""
        self._rig.clock.set_speed(speed)

    def clock(self) -> dict:
        """The clock's mode, speed [sim s per wall s], whether paused, and the time [s]."""
        clock = self._rig.clock
        return {"mode": clock.mode, "speed": clock.speed, "paused": clock.paused, "time_s": clock.now()}

    # -- faults -----------------------------------------------------------------------
    def _channel(self, device: str) -> DeviceChannel:
        try:
            return self._rig.channels[device]
        except KeyError:
            raise ValueError(f"device must be one of {sorted(self._rig.channels)}, got {device!r}") from None

    def disconnect(self, device: str) -> None:
        """Cut the line: the instrument ignores input and sends nothing until :meth:`reconnect`."""
        self._channel(device).faults.disconnected = True

    def reconnect(self, device: str) -> None:
        """Restore a line cut by :meth:`disconnect`."""
        self._channel(device).faults.disconnected = False

    def stall(self, device: str, seconds: float) -> None:
        """Make the instrument hang for ``seconds`` of wall time before its next line."""
        if seconds < 0:
            raise ValueError(f"seconds must be >= 0, got {seconds!r}")
        self._channel(device).faults.stall_s = float(seconds)

    def garble(self, device: str, replies: int = 1) -> None:
        """Corrupt the bytes of the next ``replies`` replies (terminators kept)."""
        if replies < 0:
            raise ValueError(f"replies must be >= 0, got {replies!r}")
        self._channel(device).faults.garble = int(replies)

    def burn_out_lamp(self) -> None:
        """The lamp filament breaks: no light, no current, ``STAT:LAMP?`` -> ``FAULT``."""
        self._rig.lamp.burnt_out = True

    def replace_lamp(self) -> None:
        """Fit a new lamp (clears the burn-out; output restarts its warm-up at switch-on)."""
        lamp = self._rig.lamp
        lamp.burnt_out = False
        if lamp.on:
            lamp.switched_at = self.now()

    def hit_limit(self, axis: int) -> None:
        """The next move of ``axis`` trips a hardware limit switch half way (error x04/x05)."""
        if axis not in self._rig.stage.axes:
            raise ValueError(f"axis must be one of {sorted(self._rig.stage.axes)}, got {axis!r}")
        self._rig.stage.limit_faults.add(axis)

    def camera_fault(self, active: bool = True) -> None:
        """An internal camera fault: ``ACQ`` fails with -200 while active."""
        self._rig.camera.fault = bool(active)

    def power_cycle_stage(self) -> None:
        """Switch the motion controller off and on (as ``RS``; a ``WP`` waiting for a position
        its axis never passes ends, the lines received meanwhile are lost)."""
        self._rig.stage.power_cycle()

    def clear_faults(self) -> None:
        """Remove every injected line fault, the camera fault and pending limit faults."""
        for channel in self._rig.channels.values():
            f = channel.faults
            f.disconnected, f.stall_s, f.garble = False, 0.0, 0
        self._rig.stage.limit_faults.clear()
        self._rig.camera.fault = False

    # -- sample holder ----------------------------------------------------------------
    def mount_sample(self, brdf: Brdf, handling_s: float = 60.0) -> None:
        """Put another object in the holder, e.g. a reference standard for absolute BRDF.

        The object is uniform, flat and seated square (it shares only the holder's tilt);
        :meth:`remount` puts the rig's own sample back.

        Parameters
        ----------
        brdf : callable
            The object's BRDF ``brdf(theta_i, phi_i, theta_r, phi_r)`` [1/sr], degrees.
        handling_s : float
            Simulated time the operator needs to swap samples [s].
        """
        if not callable(brdf):
            raise ValueError(f"brdf must be callable brdf(theta_i, phi_i, theta_r, phi_r), got {brdf!r}")
        scene = self._rig.scene
        scene.brdf = brdf
        scene.holder.mount_other()
        scene.forget()
        if handling_s > 0:
            self.advance(handling_s)

    def remount(self, mounting: int = 0, rotation_deg: float | None = None, spin: bool = False,
                handling_s: float = 60.0) -> None:
        """Put the rig's own sample (back) in the holder as mounting ``mounting``.

        Each mounting sits at its own place and tilt within the holder's play and shows the
        camera its own part of the texture (:mod:`drivers.emulator.texture`), drawn from the
        rig's seed and the index: the same index gives the same mounting.

        Parameters
        ----------
        mounting : int
            Index of the mounting (0: the first).
        rotation_deg : float, optional
            Rotation of the sample about its normal [deg]; None: as the operator happens to
            put it (uniform over the turn; 0 for the first mounting).
        spin : bool
            Spin the sample about the window's centre during the exposures.
        handling_s : float
            Simulated time the operator needs [s].
        """
        scene = self._rig.scene
        scene.brdf = self._rig.sample_brdf
        scene.holder.mount(int(mounting), rotation_deg, bool(spin))
        scene.forget()
        if handling_s > 0:
            self.advance(handling_s)

    # -- ground truth -----------------------------------------------------------------
    def true_state(self) -> TrueState:
        """Ground truth now (true positions, lamp output, true radiance)."""
        rig = self._rig
        t = rig.clock.now()
        positions = rig.stage.true_positions(t)
        ti, pi_, tr, pr = rig.scene.angles(positions)
        lamp = rig.lamp.output(t)
        factor = rig.scene.reflectance_factor(positions)
        return TrueState(
            time_s=t,
            positions_deg=tuple(positions),  # type: ignore[arg-type]
            theta_i=ti, phi_i=pi_, theta_r=tr, phi_r=pr,
            lamp_output=lamp,
            irradiance_w_m2=rig.scene.lamp_irradiance_w_m2 * lamp,
            radiance_w_m2_sr=rig.scene.lamp_irradiance_w_m2 * lamp * factor,
            reflectance_factor=factor,
            moving=tuple(rig.stage.axes[n].moving(t) for n in sorted(rig.stage.axes)),  # type: ignore[arg-type]
            stray_radiance_w_m2_sr=rig.scene.stray_radiance(lamp),
        )

    def expected_dn(self, exposure_s: float, gain: float = 1.0) -> float:
        """Noise-free mean DN of a pixel fully inside the sample image on the beam's axis,
        without PRNU/DSNU, for an exposure starting now with the current geometry and lamp
        output (stray light and the camera's non-linearity included) [DN]."""
        rig = self._rig
        t = rig.clock.now()
        positions = rig.stage.true_positions(t)
        lamp = rig.lamp.mean_output(t, t + exposure_s)
        radiance = rig.scene.radiance(positions, lamp) + rig.scene.stray_radiance(lamp)
        photons = radiance * rig.optics.photon_rate_per_radiance() * exposure_s
        p = rig.ccd_params
        electrons = p.quantum_efficiency * photons + p.dark_current_e_per_s * exposure_s
        signal = nonlinear_signal(p.base_gain_dn_per_e * gain * electrons, rig.systematics.nonlinearity,
                                  p.max_dn - p.offset_dn)
        return p.offset_dn + float(signal)


class EmulatedRig:
    """The whole emulated goniometer: lab world, three instruments and their transports.

    Parameters
    ----------
    brdf : callable
        Sample BRDF ``brdf(theta_i, phi_i, theta_r, phi_r) -> array`` [1/sr]; angles in
        degrees; must broadcast.
    seed : int
        Seed of every random process (fixed patterns, noise, repeatability, drift phases).
    clock_mode : {"event", "wall", "realtime"}
        How simulated time passes (:mod:`drivers.emulator.clock`): ``event`` (default,
        reproducible from the seed: time moves only when the instruments say it passes),
        ``wall`` (the wall clock times ``speed``, jumping ahead when a client waits on the
        rig) or ``realtime`` (hardware timing: waits sleep).
    speed : float
        Simulated seconds per wall second in the ``wall`` and ``realtime`` modes (> 0).
    min_separation_deg : float
        Minimum camera-lamp angle enforced by the stage interlock [deg].
    name : str
        Name for ``gonio-sim://<device>?rig=<name>`` URLs.
    lamp_warm : bool
        Start with the lamp on and warm (as if switched on an hour before) instead of
        the power-on state (off).
    motors_on : bool
        Start with the stage motors on (default: off, as a real controller powers up).
    optics, ccd_params, lamp_params : optional
        Override the rig layout and the models' constants (e.g.
        ``LampParams(flicker_rms=0.0, drift_amplitude=0.0)`` for a perfectly steady lamp).
    fixed_pattern : bool
        Include PRNU, DSNU and hot pixels in the CCD.
    lamp_irradiance_w_m2 : float
        In-band irradiance of the warm lamp at rated voltage on a surface facing it.
    monitor : bool
        Fit the lamp monitor (camera ``MONitor?``, ``*OPT?`` -> ``MON``); False gives a rig
        without one, whose camera answers ``MON?`` with -113.
    monitor_params : MonitorParams, optional
        Constants of the lamp monitor (:mod:`drivers.emulator.monitor`).
    axes : sequence of AxisConfig, optional
        Stage axis configuration (default :data:`~drivers.emulator.stage_firmware.DEFAULT_AXES`;
        e.g. another repeatability or encoder resolution).
    systematics : Systematics, optional
        The rig's systematic errors (:mod:`drivers.emulator.systematics`: axis zero
        offsets, sample tilt, stray light, camera non-linearity, beam profile); default
        none, the ideal rig. ``drivers.emulator.systematics.realism("lab", seed)`` gives
        typical magnitudes.
    """

    def __init__(self, brdf: Brdf, seed: int = 0, clock_mode: str = "event", speed: float = 1.0,
                 min_separation_deg: float = 5.0,
                 name: str = "default", lamp_warm: bool = False, motors_on: bool = False,
                 optics: Optics | None = None, ccd_params: CCDParams | None = None,
                 lamp_params: LampParams | None = None, fixed_pattern: bool = True,
                 lamp_irradiance_w_m2: float = DEFAULT_LAMP_IRRADIANCE_W_M2, monitor: bool = True,
                 monitor_params: MonitorParams | None = None,
                 axes: Sequence[AxisConfig] = DEFAULT_AXES, systematics: Systematics | None = None) -> None:
        if not callable(brdf):
            raise ValueError(f"brdf must be callable brdf(theta_i, phi_i, theta_r, phi_r), got {brdf!r}")
        if not 0.0 <= min_separation_deg < 90.0:
            raise ValueError(f"min_separation_deg must be within 0..90, got {min_separation_deg!r}")
        if lamp_irradiance_w_m2 <= 0:
            raise ValueError(f"lamp_irradiance_w_m2 must be > 0, got {lamp_irradiance_w_m2!r}")
        if systematics is not None and not isinstance(systematics, Systematics):
            raise ValueError(f"systematics must be a drivers.emulator.systematics.Systematics, got {systematics!r}")
        self.systematics = systematics or Systematics()
        self.name = name
        self.seed = seed
        self.min_separation_deg = float(min_separation_deg)
        self.optics = optics or Optics()
        self.ccd_params = ccd_params or CCDParams(width=self.optics.width, height=self.optics.height)
        seeds = np.random.SeedSequence(seed).spawn(8)
        rngs = [np.random.default_rng(s) for s in seeds]
        self.clock = SimClock(clock_mode, speed=speed)
        self.lamp = Lamp(params=lamp_params or LampParams(), seed=int(seeds[0].generate_state(1)[0]))
        if lamp_warm:
            self.lamp.switch(True, t=-3600.0)
        self.stage = Esp300Firmware(self.clock, rngs[1], interlock=self._interlock, axes=tuple(axes),
                                    baudrate=BAUDRATES["stage"])
        if motors_on:
            for axis in self.stage.axes.values():
                axis.motor_on = True
        self.sensor = CCDSensor(self.ccd_params, seed=seeds[2], fixed_pattern=fixed_pattern,
                                nonlinearity=self.systematics.nonlinearity)
        self.sample_brdf = brdf
        self.scene = Scene(brdf, self.optics, self.lamp, self.stage, lamp_irradiance_w_m2, rngs[3],
                           systematics=self.systematics, holder=SampleHolder(self.systematics, seed, self.optics))
        self.monitor = LampMonitor(monitor_params or MonitorParams(), rngs[7]) if monitor else None
        self.camera = CameraFirmware(self.clock, self.sensor, self.optics, self.scene, rngs[4],
                                     monitor=self.monitor)
        self.lamp_supply = LampFirmware(self.clock, self.lamp, rngs[5])
        self.channels = {
            "stage": DeviceChannel("stage", self.stage, self.clock, BAUDRATES["stage"]),
            "camera": DeviceChannel("camera", self.camera, self.clock, BAUDRATES["camera"]),
            "lamp": DeviceChannel("lamp", self.lamp_supply, self.clock, BAUDRATES["lamp"]),
        }
        for k, channel in enumerate(self.channels.values()):
            channel.faults.rng = np.random.default_rng(seeds[6].spawn(3)[k])
        self.control = RigControl(self)
        self._transports: dict[str, list] = {d: [] for d in self.channels}
        self._started = False

    def _interlock(self, positions: tuple[float, ...]) -> bool:
        a1, a2, a3 = positions
        return separation_deg(a1, a2, a3) >= self.min_separation_deg

    # -- transports -------------------------------------------------------------------
    def start(self, pty: bool = True, tcp: bool = False, tcp_ports: dict[str, int] | None = None,
              symlinks: dict[str, str] | None = None, check_baudrate: bool = True) -> dict[str, dict[str, str]]:
        """Open the transports and register the rig for ``gonio-sim://`` URLs.

        Parameters
        ----------
        pty : bool
            Open a raw-mode pseudo-terminal per instrument.
        tcp : bool
            Listen on 127.0.0.1 per instrument.
        tcp_ports : dict, optional
            Fixed TCP port per device (default: free ports).
        symlinks : dict, optional
            Symlink path per device pointing at its pseudo-terminal.
        check_baudrate : bool
            Garble a pseudo-terminal's traffic while the client's baud rate differs from the
            instrument's, as a real line would (:class:`~drivers.emulator.transports.PtyTransport`);
            False lets any rate through.

        Returns
        -------
        dict
            ``{device: {"url": ..., "pty": ..., "tcp": ...}}`` (the kinds opened).
        """
        if self._started:
            raise RuntimeError(f"rig {self.name!r} is already started")
        with _RIGS_LOCK:
            other = _RIGS.get(self.name)
            if other is not None and other is not self:
                raise ValueError(f"an emulated rig named {self.name!r} is already running in this process")
            _RIGS[self.name] = self
        if "drivers.emulator" not in serial.protocol_handler_packages:
            serial.protocol_handler_packages.append("drivers.emulator")
        try:
            for device, channel in self.channels.items():
                if pty:
                    link = (symlinks or {}).get(device)
                    self._transports[device].append(("pty", PtyTransport(channel, symlink=link,
                                                                         check_baudrate=check_baudrate)))
                if tcp:
                    port = (tcp_ports or {}).get(device, 0)
                    self._transports[device].append(("tcp", TcpTransport(channel, port=port)))
        except Exception:
            self.close()
            raise
        self._started = True
        return self.addresses()

    def url(self, device: str) -> str:
        """``gonio-sim://<device>?rig=<name>`` for the in-process pyserial handler."""
        if device not in self.channels:
            raise ValueError(f"device must be one of {sorted(self.channels)}, got {device!r}")
        return f"gonio-sim://{device}?rig={self.name}"

    def addresses(self) -> dict[str, dict[str, str]]:
        """Every address of every instrument: ``{device: {"url", "pty", "tcp"}}``."""
        out: dict[str, dict[str, str]] = {}
        for device in self.channels:
            entry = {"url": self.url(device)}
            for kind, transport in self._transports[device]:
                entry[kind] = transport.address
            out[device] = entry
        return out

    def close(self) -> None:
        """Stop every transport and unregister the rig."""
        for transports in self._transports.values():
            for _, transport in transports:
                transport._stop.set()  # signal every thread first, then join them
        for transports in self._transports.values():
            for _, transport in transports:
                transport.close()
            transports.clear()
        with _RIGS_LOCK:
            if _RIGS.get(self.name) is self:
                del _RIGS[self.name]
        self._started = False

    def __enter__(self) -> "EmulatedRig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

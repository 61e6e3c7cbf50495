"""Incandescent lamp model: voltage power laws, warm-up, drift, flicker and burn-out.

The rig's source is a 300 W incandescent lamp (Oren & Nayar 1995, section 5).  Its output
in the camera's band scales steeply with the supply voltage; the standard engineering
power laws for tungsten-filament lamps near rated voltage are

    flux ~ V^3.4,   current ~ V^0.55 (so power ~ V^1.55),   life ~ V^-13

(IES Lighting Handbook, 9th ed., "Incandescent filament lamps", voltage characteristics;
summarised in Wikipedia, "Incandescent light bulb", section "Electrical characteristics").
The luminous-flux exponent is used for the in-band output, a documented simplification
(the exponent of a narrow band near 550 nm is close to the luminous one).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LampParams", "Lamp", "relative_output_steady"]


@dataclass(frozen=True)
class LampParams:
    """Constants of the lamp model.

    Attributes
    ----------
    nominal_voltage_v : float
        Rated voltage [V].
    nominal_current_a : float
        Current at rated voltage, hot filament [A] (300 W / 120 V).
    flux_exponent : float
        Output ~ V^flux_exponent [-] (3.4, IES handbook).
    current_exponent : float
        Current ~ V^current_exponent [-] (0.55).
    filament_time_constant_s : float
        Thermal time constant of the filament [s]: output and current settle after
        switch-on (and output decays after switch-off) with it.
    cold_resistance_ratio : float
        Cold / hot filament resistance [-]; the inrush current at switch-on is the hot
        current divided by it.
    warmup_deficit : float
        Relative output deficit right after the filament is hot [-]; it decays with
        ``warmup_time_constant_s`` (bulb, socket and reflector warming up).
    warmup_time_constant_s : float
        Time constant of the warm-up [s].
    drift_amplitude : float
        Relative amplitude of each of the two slow drift components [-].
    drift_periods_s : tuple of float
        Periods of the drift components [s].
    flicker_rms : float
        Relative rms output fluctuation of a 10 ms exposure [-]; it scales as
        ``1 / sqrt(exposure / 10 ms)`` for longer exposures (independent fluctuations
        average out).
    voltage_noise_rms : float
        Relative rms noise of the voltage read-back [-].
    current_noise_rms : float
        Relative rms noise of the current read-back [-].
    max_voltage_v : float
        Largest voltage setpoint [V].
    """

    nominal_voltage_v: float = 120.0
    nominal_current_a: float = 2.5
    flux_exponent: float = 3.4
    current_exponent: float = 0.55
    filament_time_constant_s: float = 0.15
    cold_resistance_ratio: float = 1.0 / 14.0
    warmup_deficit: float = 0.02
    warmup_time_constant_s: float = 120.0
    drift_amplitude: float = 0.0005
    drift_periods_s: tuple[float, float] = (900.0, 3700.0)
    flicker_rms: float = 0.0005
    voltage_noise_rms: float = 0.0005
    current_noise_rms: float = 0.0005
    max_voltage_v: float = 132.0


def relative_output_steady(voltage_v: float, params: LampParams = LampParams()) -> float:
    """Steady-state output relative to the output at rated voltage: ``(V / V0)^3.4`` [-].

    Examples
    --------
    >>> round(relative_output_steady(108.0), 4)   # 10 % under-voltage: 30 % less light
    0.6989
    """
    if voltage_v < 0:
        raise ValueError(f"voltage_v must be >= 0, got {voltage_v!r}")
    return (voltage_v / params.nominal_voltage_v) ** params.flux_exponent


@dataclass
class Lamp:
    """State of the lamp and its supply output, evaluated at simulated times [s].

    The output (relative to a warm lamp at rated voltage) is, while on,

        (V/V0)^3.4 * (1 - exp(-dt/tau_f)) * (1 - w exp(-dt/tau_w)) * (1 + drift(t))

    with ``dt`` the time since switch-on; after switch-off it decays as ``exp(-dt/tau_f)``.
    A burnt-out lamp gives nothing.  Voltage changes while on take effect at once (the
    filament's response to small steps is ignored).

    Examples
    --------
    >>> lamp = Lamp(seed=1)
    >>> lamp.switch(True, t=0.0)
    >>> round(lamp.output(600.0) / relative_output_steady(120.0), 2)
    1.0
    """

    params: LampParams = field(default_factory=LampParams)
    seed: int = 0
    voltage_setpoint_v: float = 120.0
    on: bool = False
    burnt_out: bool = False
    switched_at: float = -1e9
    _level_at_switch_off: float = 0.0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        self._drift_phases = rng.uniform(0, 2 * np.pi, size=len(self.params.drift_periods_s))

    def drift(self, t: float) -> float:
        """Slow relative drift of the output [-] (two sinusoids with seeded phases)."""
        p = self.params
        return float(
            sum(p.drift_amplitude * np.sin(2 * np.pi * t / period + phase)
                for period, phase in zip(p.drift_periods_s, self._drift_phases))
        )

    def switch(self, on: bool, t: float) -> None:
        """Switch the supply output on or off at time ``t``."""
        if on == self.on:
            return
        if not on:
            self._level_at_switch_off = self.output(t)
        self.on = on
        self.switched_at = t

    def set_voltage(self, voltage_v: float) -> None:
        """Change the voltage setpoint [V]; ValueError outside 0..max_voltage_v."""
        if not 0.0 <= voltage_v <= self.params.max_voltage_v:
            raise ValueError(f"voltage must be within 0..{self.params.max_voltage_v:g} V, got {voltage_v!r}")
        self.voltage_setpoint_v = float(voltage_v)

    def output(self, t: float) -> float:
        """Output relative to a warm lamp at rated voltage at time ``t`` [-] (no flicker)."""
        p = self.params
        dt = max(t - self.switched_at, 0.0)
        if self.burnt_out:
            return 0.0
        if not self.on:
            return self._level_at_switch_off * float(np.exp(-dt / p.filament_time_constant_s))
        filament = -np.expm1(-dt / p.filament_time_constant_s)
        warm = 1.0 - p.warmup_deficit * np.exp(-dt / p.warmup_time_constant_s)
        return float(relative_output_steady(self.voltage_setpoint_v, p) * filament * warm * (1.0 + self.drift(t)))

    def settled(self, t: float, tolerance: float = 1e-3) -> bool:
        """Whether the warm-up and the filament's rise are within ``tolerance`` of steady state at ``t``.

        True once both transient terms of :meth:`output` have decayed below ``tolerance``
        (relative): ``dt >= tau_f ln(1/tol)`` and ``dt >= tau_w ln(w/tol)`` after switch-on
        (366 s with the defaults).  False while the output is off.

        Examples
        --------
        >>> lamp = Lamp(); lamp.switch(True, t=0.0)
        >>> lamp.settled(300.0), lamp.settled(400.0)
        (False, True)
        """
        if not self.on:
            return False
        p = self.params
        dt = t - self.switched_at
        filament = p.filament_time_constant_s * np.log(1.0 / tolerance)
        warm = p.warmup_time_constant_s * np.log(p.warmup_deficit / tolerance) if p.warmup_deficit > tolerance else 0.0
        return bool(dt >= max(filament, warm))

    def mean_output(self, t0: float, t1: float, n: int = 9) -> float:
        """Mean of :meth:`output` over [t0, t1] (Simpson's rule on ``n`` points) [-]."""
        if t1 <= t0:
            return self.output(t0)
        ts = np.linspace(t0, t1, n)
        values = np.array([self.output(t) for t in ts])
        weights = np.ones(n)
        weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
        return float(weights @ values / weights.sum())

    def flicker_factor(self, exposure_s: float, rng: np.random.Generator) -> float:
        """Random relative output factor of one exposure (mean 1) [-]."""
        rms = self.params.flicker_rms * np.sqrt(0.01 / max(exposure_s, 0.01))
        return float(1.0 + rms * rng.standard_normal())

    def current(self, t: float) -> float:
        """Lamp current [A] at time ``t`` (noise-free), with the cold-filament inrush."""
        p = self.params
        if self.burnt_out or not self.on:
            return 0.0
        hot = p.nominal_current_a * (self.voltage_setpoint_v / p.nominal_voltage_v) ** p.current_exponent
        dt = max(t - self.switched_at, 0.0)
        inrush = (1.0 / p.cold_resistance_ratio - 1.0) * np.exp(-dt / p.filament_time_constant_s)
        return float(hot * (1.0 + inrush))

    def voltage(self) -> float:
        """Output voltage [V] (noise-free): the setpoint when on, 0 when off."""
        return self.voltage_setpoint_v if self.on else 0.0

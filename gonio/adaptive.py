"""Adaptive runs: after each batch of points the current posterior chooses the next batch,
until the parameters are as certain as asked or the instrument time is spent
(``gonio run --adaptive``).

A fixed design (:mod:`gonio.design`) is chosen before anything is measured, over the
prior; an adaptive run measures a starting protocol, fits it, and chooses every later batch
for the parameters the data now point at (sequential Bayesian design: Chaloner & Verdinelli
1995, section 5; NIST's optbayesexpt does this with a particle filter for lab instruments,
without the motion's cost). Each round:

1. **Fit** the recording so far by least squares with the rig's errors
   (:func:`gonio.analysis.load_data`, :func:`gonio.fitting.fit`: calibration per incidence,
   the alignment and the stray light free by default, as a fit of a real rig's recording
   needs, docs/design.md), starting from the previous round's values. Its 95 % intervals
   (``value +- 1.96`` standard errors, the Laplace approximation) are compared with the
   targets (``until``): all narrower, the run ends.
2. **Budget.** The run's instrument time is its protocol's ``gonio plan`` estimate (within
   3 % of the recordings, docs/protocols.md), lamp warm-up not included: what is left of
   ``budget``, at most ``batch_seconds``, is this batch's. Nothing affordable left, the run
   ends.
3. **Choose** the batch as :func:`gonio.design.design` does (the same candidates, the rig's
   own refusal rule, Ds-optimality with the calibration and the alignment marginalised,
   greedy by gain per second), with three changes: the criterion is the information about
   the targets' parameters alone (the model's other parameters are nuisance too), it
   averages over draws from the fit's posterior (Gaussian, within the prior ranges) instead
   of the prior, and it starts from the information of the points already measured, so that
   a batch adds what the recording lacks. The noise per value is the recording's (the
   median relative uncertainty of its values, times the square root of the fit's reduced
   chi-square when that exceeds 1). With a calibration per incidence the lamp polar angles are those at
   which the protocol reads the reference standard (a new one would need the standard
   mounted again, two swaps of the sample).
4. **Append** the batch as ``[[block]]`` sections named ``adaptive N: ...`` with a comment
   saying from which posterior and why (:func:`gonio.protocols.extended`); the run measures
   them in the same session (:func:`gonio.acquisition.run_protocol`, ``extend``).

The recording says which points were chosen adaptively (their block names), and
``metadata.json`` ``extensions`` holds every round's decision: the fit (values, standard
errors, 95 % widths, reduced chi-square), the batch's points and estimated time, and the
stop's reason. An interrupted adaptive run resumes where it stopped (``--resume``): the
recording's protocol is the extended one.

References
----------
K. Chaloner and I. Verdinelli, "Bayesian experimental design: a review", Statistical
Science 10 (1995) 273-304.
R. D. McMichael, S. M. Blakley and S. Dushenko, "Optbayesexpt: sequential Bayesian
experiment design for adaptive measurements", J. Res. NIST 126 (2021) 126002.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from . import models
from .acquisition import Extension, RunResult
from .design import (
    ALIGNMENT_NUISANCE,
    DEFAULT_ALIGNMENT_SD,
    DEFAULT_CALIBRATION,
    PRIOR_DRAWS,
    DsCriterion,
    check_priors,
    candidate_geometries,
    greedy_selection,
    information_vectors,
    prior_information,
)
from .protocols import Protocol, extended, plan

__all__ = ["AdaptiveSettings", "AdaptiveRun", "Posterior", "batch_text", "next_batch", "DEFAULT_BATCH_SECONDS"]

#: Instrument time of one batch [s] (at most): a few lamp directions' worth of points, so
#: that the posterior steers the run often, against a fit per batch.
DEFAULT_BATCH_SECONDS = 60.0
#: z of a two-sided 95 % interval.
_Z95 = 1.959964


@dataclass(frozen=True)
class AdaptiveSettings:
    """What an adaptive run aims at and how it fits.

    Attributes
    ----------
    model : str
        Registered model fitted after each batch.
    until : dict
        ``{parameter: width}``: the run ends when every one's 95 % interval is at most this
        wide (in the parameter's unit).
    budget : float
        The most instrument time the whole protocol may take [s] (``gonio plan``'s
        estimate, lamp warm-up not included).
    priors : dict
        ``{parameter: (low, high)}``: uniform priors of the parameters fitted and designed
        for; every parameter named in ``until`` needs one.
    fixed : dict
        Values of the model's other parameters.
    batch_seconds : float
        Instrument time of one batch, at most [s].
    calibration : {"per-incidence", "common"}
        The recording's calibration in the fit (:func:`gonio.analysis.load_data`).
    alignment : str or tuple of str
        The rig's alignment errors freed in the fit (``"all"``, names, or ``()``).
    stray_light : bool
        Fit the rig's stray light.
    alignment_sd : float
        Prior standard deviation of the alignment errors the design marginalises [deg].
    max_angle : float
        Largest lamp and camera angle from the normal considered [deg].
    azimuths : tuple of float
        Lamp azimuths considered [deg].
    seed : int
        Seed of the fits and the posterior draws.
    """

    model: str
    until: dict[str, float]
    budget: float
    priors: dict[str, tuple[float, float]]
    fixed: dict[str, float] = field(default_factory=dict)
    batch_seconds: float = DEFAULT_BATCH_SECONDS
    calibration: str = "per-incidence"
    alignment: str | tuple[str, ...] = "all"
    stray_light: bool = True
    alignment_sd: float = DEFAULT_ALIGNMENT_SD
    max_angle: float = 90.0
    azimuths: tuple[float, ...] = (0.0,)
    seed: int = 0

    def __post_init__(self) -> None:
        spec = models.get(self.model)
        check_priors(spec, self.priors, self.fixed)
        if not self.until:
            raise ValueError("until: expected at least one target width, e.g. sigma=0.5")
        for name, width in self.until.items():
            if name not in spec.param_names:
                raise ValueError(f"until {name}: not a parameter of {self.model!r}; its parameters are "
                                 f"{list(spec.param_names)}")
            if not (math.isfinite(width) and width > 0):
                raise ValueError(f"until {name}={width:g}: expected a 95 % interval width > 0")
            if name not in self.priors:
                raise ValueError(f"until {name}: give its prior range too (e.g. --prior {name}=LOW:HIGH)")
        if not (math.isfinite(self.budget) and self.budget > 0):
            raise ValueError(f"budget {self.budget:g} s: expected an instrument time > 0")
        if not (math.isfinite(self.batch_seconds) and self.batch_seconds > 0):
            raise ValueError(f"batch {self.batch_seconds:g} s: expected an instrument time > 0")
        if self.calibration not in ("per-incidence", "common"):
            raise ValueError(f"calibration {self.calibration!r}: expected 'per-incidence' or 'common'")

    def to_json(self) -> dict[str, Any]:
        """The settings as stored with the recording."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class Posterior:
    """The fit of the recording so far (least squares with the rig's errors).

    Attributes
    ----------
    values, stderr : dict
        Best-fit value and standard error of the designed-for parameters.
    covariance : ndarray
        Their covariance, in the order of ``values``.
    redchi : float
        Reduced chi-square of the fit.
    points : int
        Values fitted.
    start : dict
        Every fitted value (the next round's starting point).
    relative_noise : float
        Noise of one value relative to it [-]: the median stated relative uncertainty,
        times the square root of the reduced chi-square when that exceeds 1.
    """

    values: dict[str, float]
    stderr: dict[str, float]
    covariance: np.ndarray
    redchi: float
    points: int
    start: dict[str, float]
    relative_noise: float

    @property
    def widths(self) -> dict[str, float]:
        """95 % interval widths, ``2 x 1.96`` standard errors (inf where undetermined)."""
        return {n: (2 * _Z95 * s if math.isfinite(s) else math.inf) for n, s in self.stderr.items()}

    def summary(self) -> str:
        """e.g. ``"sigma = 30.1 +- 0.21, rho = 0.9 +- 0.004 (95 %), reduced chi-square 1.1, 60 values"``."""
        parts = ", ".join(f"{n} = {v:.5g} +- {w / 2:.3g}" for (n, v), w in zip(self.values.items(),
                                                                                self.widths.values()))
        return f"{parts} (95 %), reduced chi-square {self.redchi:.3g}, {self.points} values"

    def to_json(self) -> dict[str, Any]:
        return {"values": self.values, "stderr": self.stderr, "widths": self.widths, "redchi": self.redchi,
                "points": self.points, "relative_noise": self.relative_noise}


def fit_posterior(folder: str | Path, settings: AdaptiveSettings, start: Mapping[str, float] | None = None
                  ) -> Posterior:
    """Fit the recording in ``folder`` as the run is set to (``settings``), by least squares
    from ``start``."""
    from .analysis import load_data
    from .fitting import fit
    from .fitting.priors import Uniform

    dataset, data_priors = load_data(folder, calibration=settings.calibration)
    priors = {**data_priors, **{n: Uniform(*r) for n, r in settings.priors.items()}}
    alignment = settings.alignment or None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own flags say what a user needs; here only the numbers count
        result = fit(dataset, settings.model, fixed=settings.fixed, priors=priors, mcmc=False, jitter="auto",
                     start=start, seed=settings.seed, alignment=alignment, stray_light=settings.stray_light,
                     polish_table=False)
    ls = result.least_squares
    names = list(settings.priors)
    index = [ls.free.index(n) for n in names]
    covariance = np.asarray(ls.covariance, float)[np.ix_(index, index)]
    noise = float(np.median(dataset.sigma / np.abs(dataset.value))) * math.sqrt(max(ls.redchi, 1.0))
    return Posterior({n: float(ls.values[n]) for n in names}, {n: float(ls.stderr[n]) for n in names}, covariance,
                     float(ls.redchi), int(dataset.n), {k: float(v) for k, v in ls.values.items()}, noise)


def posterior_draws(posterior: Posterior, priors: Mapping[str, tuple[float, float]], count: int,
                    seed: int) -> np.ndarray:
    """``count`` draws of the designed-for parameters from the posterior's Gaussian
    approximation, clipped into the prior ranges, (count, P); the mean alone when the
    covariance is undetermined."""
    mean = np.array(list(posterior.values.values()))
    if not np.all(np.isfinite(posterior.covariance)):
        draws = np.repeat(mean[None], count, axis=0)
    else:
        draws = np.random.default_rng(seed).multivariate_normal(mean, posterior.covariance, size=count, method="eigh")
    ranges = np.array(list(priors.values()), float)
    return np.clip(draws, ranges[:, 0], ranges[:, 1])


def reference_incidences(protocol: Protocol) -> set[float]:
    """Lamp polar angles at which the protocol reads its reference standard [deg]."""
    if protocol.reference is None:
        return set()
    return {round(float(g[0]), 6) for g in protocol.reference.geometries}


def next_batch(protocol: Protocol, posterior: Posterior, settings: AdaptiveSettings, seconds: float
               ) -> tuple[np.ndarray, float]:
    """The geometries of the next batch, (K, 3) rig geometry, and the time they add to the
    protocol's estimate [s] (module notes, step 3); an empty batch when nothing fits into
    ``seconds``."""
    # the targets' parameters first: the criterion is their information, the others are nuisance (Ds)
    names = sorted(settings.priors, key=lambda name: name not in settings.until)
    order = [list(settings.priors).index(name) for name in names]
    widths = np.array([settings.priors[name][1] - settings.priors[name][0] for name in names])
    alignment = ALIGNMENT_NUISANCE if settings.alignment_sd > 0 else ()
    candidates = candidate_geometries(protocol.rig, 5.0, 5.0, settings.azimuths, settings.max_angle)
    if settings.calibration == "per-incidence":
        allowed = reference_incidences(protocol)
        candidates = candidates[np.isin(np.round(candidates[:, 0], 6), sorted(allowed))]
    if len(candidates) == 0:
        return np.empty((0, 3)), 0.0
    draws = posterior_draws(posterior, settings.priors, PRIOR_DRAWS, settings.seed)[:, order]

    def vectors(points: np.ndarray) -> np.ndarray:
        return information_vectors(settings.model, points, draws, names, settings.fixed, widths,
                                   posterior.relative_noise, alignment)

    planned = plan(protocol)
    measured = np.array([(p.theta_i, p.phi_i, p.view) for p in planned.points], float).reshape(-1, 3)
    known = vectors(measured)
    information = (prior_information(widths, DEFAULT_CALIBRATION, settings.alignment_sd, len(alignment))[None]
                   + np.einsum("dkp,dkq->dpq", known, known))
    criterion = DsCriterion(vectors(candidates), information, len(settings.until))
    base = planned.estimated_seconds

    def added_seconds(points: np.ndarray) -> float:
        return plan(extended(protocol, batch_text(points, 0))).estimated_seconds - base

    chosen, seconds_added = greedy_selection(candidates, protocol.rig, seconds, criterion.gains, criterion.add,
                                             added_seconds)
    return candidates[chosen], seconds_added


def batch_text(points: np.ndarray, number: int, why: str = "") -> str:
    """The batch as ``[[block]]`` sections, one per lamp direction, named ``adaptive N:
    theta_i=..., phi_i=...``, after a comment saying why."""
    blocks: dict[tuple[float, float], list[float]] = {}
    for theta_i, phi_i, view in sorted(map(tuple, np.asarray(points, float).tolist()), key=lambda p: (p[1], p[0], p[2])):
        blocks.setdefault((theta_i, phi_i), []).append(view)
    text = "".join(f"# {line}\n" for line in why.splitlines())
    for (theta_i, phi_i), views in blocks.items():
        text += (f"[[block]]\nname = \"adaptive {number}: theta_i={theta_i:g}, phi_i={phi_i:g}\"\n"
                 f"theta_i = {theta_i:g}\nphi_i = {phi_i:g}\nview = [{', '.join(f'{v:g}' for v in views)}]\n")
    return text


class AdaptiveRun:
    """The ``extend`` callback of an adaptive run (:func:`gonio.acquisition.run_protocol`).

    Parameters
    ----------
    folder : path
        The recording.
    protocol : Protocol
        The protocol being measured (the starting one, or the extended one of a resumed run).
    settings : AdaptiveSettings
    batches : int
        Batches already appended (a resumed run's).
    say : callable, optional
        Called with a line of text at each decision (the command line prints them).
    """

    def __init__(self, folder: str | Path, protocol: Protocol, settings: AdaptiveSettings, batches: int = 0,
                 say: Callable[[str], None] | None = None) -> None:
        self.folder, self.protocol, self.settings = Path(folder), protocol, settings
        self.batches, self.say = batches, say or (lambda text: None)
        self.start: dict[str, float] | None = None
        self.last: Posterior | None = None

    def __call__(self, result: RunResult) -> Extension:
        """Fit the recording so far and decide: the next batch, or the end of the run."""
        settings = self.settings
        try:
            posterior = fit_posterior(self.folder, settings, self.start)
        except (ValueError, RuntimeError, np.linalg.LinAlgError) as error:  # the recording is kept whole
            return self._stop({"batch": self.batches, "settings": settings.to_json()},
                              f"the fit of the recording so far failed ({type(error).__name__}: {error}); nothing "
                              "more is chosen. Fit it with gonio fit to see why, or start from a longer protocol")
        self.start, self.last = posterior.start, posterior
        spent = plan(self.protocol).estimated_seconds
        note: dict[str, Any] = {"batch": self.batches, "posterior": posterior.to_json(), "estimated_seconds": spent,
                                "settings": settings.to_json()}
        self.say(f"after {posterior.points} values ({spent:.0f} s of {settings.budget:.0f} s): {posterior.summary()}")
        wide = {n: w for n, w in posterior.widths.items() if n in settings.until and w > settings.until[n]}
        if not wide:
            return self._stop(note, "target reached: " + ", ".join(
                f"{n} {posterior.widths[n]:.4g} <= {w:g}" for n, w in settings.until.items()))
        seconds = min(settings.batch_seconds, settings.budget - spent)
        points, added = next_batch(self.protocol, posterior, settings, seconds) if seconds > 0 else (np.empty((0, 3)), 0.0)
        still = "still wider than asked: " + ", ".join(f"{n} {w:.4g} > {settings.until[n]:g}" for n, w in wide.items())
        if len(points) == 0:
            return self._stop(note, f"budget spent: {spent:.0f} s of {settings.budget:.0f} s estimated, no point fits "
                                    f"into the {max(seconds, 0.0):.0f} s left; {still}")
        return self._append(note, posterior, points, added, still)

    def _append(self, note: dict[str, Any], posterior: Posterior, points: np.ndarray, added: float,
                still: str) -> Extension:
        """The next batch as an :class:`Extension`, with the comment and note saying why."""
        self.batches += 1
        why = (f"adaptive batch {self.batches}: {len(points)} points, {added:.0f} s, chosen after {posterior.points} "
               f"values from the posterior {posterior.summary()};\n{still}")
        text = batch_text(points, self.batches, why)
        self.protocol = extended(self.protocol, text)
        self.say(f"batch {self.batches}: {len(points)} points, {added:.0f} s")
        return Extension(text, {**note, "batch": self.batches, "reason": why.replace("\n", " "),
                                "points": np.asarray(points).tolist(), "added_seconds": added})

    def _stop(self, note: dict[str, Any], reason: str) -> Extension:
        self.say(f"adaptive run stopped: {reason}")
        return Extension(None, {**note, "stopped": reason})


def appended_batches(metadata: Mapping[str, Any]) -> int:
    """Batches an adaptive recording's metadata says were appended."""
    return sum(1 for entry in metadata.get("extensions", []) if entry.get("appended"))


def resume_protocol(metadata: Mapping[str, Any], protocol: Protocol) -> Protocol:
    """The protocol an adaptive recording was extended to, checked to continue ``protocol``
    (the one given to resume it).

    Raises
    ------
    ValueError
        The recording's protocol does not begin with ``protocol``'s text.
    """
    from .protocols import loads

    stored = metadata["protocol"]["text"]
    if not stored.startswith(protocol.text.rstrip("\n")):
        raise ValueError(f"{protocol.source}: the recording was not started from this protocol (its protocol text "
                         "begins differently); give the protocol it was started with")
    return loads(stored, source=protocol.source)

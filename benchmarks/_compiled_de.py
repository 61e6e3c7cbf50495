"""A compiled differential-evolution MCMC sampler of the Oren-Nayar likelihood: the
reference a Python fitter is held against (benchmarks/bench_fitting_grazing.py).

ter Braak (2006), "A Markov chain Monte Carlo version of the genetic algorithm Differential
Evolution", Statistics and Computing 16: each walker in turn proposes
``x + gamma (x_r1 - x_r2) + e`` from two other walkers of the current population,
``gamma = 2.38 / sqrt(2 d)`` (1 every tenth generation, to jump between modes), ``e`` a
small Gaussian jitter, accepted by the Metropolis rule; the whole loop, the model and the
likelihood in one numba function, no Python per step. The model is Oren & Nayar (1995)
eq 33-35 with the interreflection weight 1 and the floor at 0, written here from the
paper (as the plain baseline of bench_fitting.py writes it), uniform priors rho in (0, 1],
sigma in [0, 90] deg.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _log_likelihood(rho, sigma_deg, ti, tr, dphi, value, sd):
    if not (0.0 < rho <= 1.0 and 0.0 <= sigma_deg <= 90.0):
        return -np.inf
    s2 = math.radians(sigma_deg) ** 2
    c1 = 1.0 - 0.5 * s2 / (s2 + 0.33)
    a2 = 0.45 * s2 / (s2 + 0.09)
    a3 = 0.125 * s2 / (s2 + 0.09)
    inter = 0.17 * rho * rho / math.pi * s2 / (s2 + 0.13)
    total = 0.0
    for k in range(ti.shape[0]):
        alpha, beta, cos = max(ti[k], tr[k]), min(ti[k], tr[k]), math.cos(dphi[k])
        c2 = a2 * (math.sin(alpha) if cos >= 0 else math.sin(alpha) - (2 * beta / math.pi) ** 3)
        c3 = a3 * (4 * alpha * beta / math.pi ** 2) ** 2
        direct = rho / math.pi * (c1 + cos * c2 * math.tan(beta)
                                  + (1 - abs(cos)) * c3 * math.tan((alpha + beta) / 2))
        model = max(direct + inter * (1 - cos * (2 * beta / math.pi) ** 2), 0.0)
        z = (model - value[k]) / sd[k]
        total += z * z
    return -0.5 * total


@njit(cache=True)
def de_mcmc(start, n_steps, seed, ti, tr, dphi, value, sd):
    """Chain (n_steps, walkers, 2) of (rho, sigma [deg]) from ``start`` (walkers, 2);
    angles in radians."""
    np.random.seed(seed)
    walkers = start.shape[0]
    x = start.copy()
    lp = np.empty(walkers)
    for w in range(walkers):
        lp[w] = _log_likelihood(x[w, 0], x[w, 1], ti, tr, dphi, value, sd)
    chain = np.empty((n_steps, walkers, 2))
    scale = 2.38 / math.sqrt(4.0)
    for step in range(n_steps):
        gamma = 1.0 if step % 10 == 9 else scale
        for w in range(walkers):
            r1 = w
            while r1 == w:
                r1 = np.random.randint(walkers)
            r2 = w
            while r2 == w or r2 == r1:
                r2 = np.random.randint(walkers)
            p0 = x[w, 0] + gamma * (x[r1, 0] - x[r2, 0]) + 1e-6 * np.random.normal()
            p1 = x[w, 1] + gamma * (x[r1, 1] - x[r2, 1]) + 1e-6 * np.random.normal()
            candidate = _log_likelihood(p0, p1, ti, tr, dphi, value, sd)
            if math.log(np.random.random()) < candidate - lp[w]:
                x[w, 0], x[w, 1], lp[w] = p0, p1, candidate
        chain[step] = x
    return chain

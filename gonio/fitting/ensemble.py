"""The ensemble sampler's loop: emcee's moves driven over preallocated arrays.

``emcee.EnsembleSampler`` spends, per step, more on its bookkeeping than gonio's
vectorised likelihood costs: it converts every walker's log posterior one by one, copies
its random state, checks the state and, run in pieces as the convergence checks need,
re-allocates the whole chain every time it grows. :class:`EnsembleChain` is that loop
without those costs: the same moves (any ``emcee.moves.Move``, chosen per step with
emcee's rule ``random.choice(moves, p=weights)``), the same random stream, the chain in
arrays that double when full. With the same moves and random state it produces
``EnsembleSampler``'s chain bit for bit (tests/fitting/test_mcmc.py).

References
----------
D. Foreman-Mackey, D. W. Hogg, D. Lang, J. Goodman, "emcee: The MCMC Hammer", PASP 125,
306 (2013).
"""
from __future__ import annotations

from typing import Callable, Sequence

import emcee
import numpy as np

__all__ = ["EnsembleChain"]


class EnsembleChain:
    """An ensemble of walkers advanced by emcee moves, its chain kept in memory.

    Parameters
    ----------
    log_prob_batch : callable
        ``log_prob_batch(coords) -> ndarray``: log posterior of every row of ``coords``
        (shape (W, d)); ``-inf`` outside the support, never NaN.
    moves : sequence of (emcee.moves.Move, float)
        Moves and their relative weights; each step uses one, drawn as emcee draws it.
    coords : numpy.ndarray, shape (W, d)
        Start positions (inside the support).
    random : numpy.random.RandomState
        The random state of the moves (emcee's moves use the legacy interface).

    Raises
    ------
    ValueError
        A start position has a non-finite log posterior, or the log posterior returns NaN.
    """

    def __init__(self, log_prob_batch: Callable[[np.ndarray], np.ndarray],
                 moves: Sequence[tuple[emcee.moves.Move, float]], coords: np.ndarray,
                 random: np.random.RandomState) -> None:
        self._batch = log_prob_batch
        self.moves = [move for move, _ in moves]
        weights = np.array([weight for _, weight in moves], float)
        self.weights = weights / weights.sum()
        # the move of a step is drawn as RandomState.choice(moves, p=weights) draws it
        # (emcee.EnsembleSampler): one uniform number against the cumulative weights
        self._cumulative = self.weights.cumsum()
        self._cumulative /= self._cumulative[-1]
        self.random = random
        self._model = emcee.model.Model(log_prob_fn=log_prob_batch, compute_log_prob_fn=self._log_prob,
                                        map_fn=map, random=random)
        coords = np.array(coords, float)
        log_prob, _ = self._log_prob(coords)
        if not np.all(np.isfinite(log_prob)):
            raise ValueError(f"start position of walker {int(np.argmin(np.isfinite(log_prob)))} has zero posterior density")
        self.state = emcee.State(coords, log_prob=log_prob)
        self._chain = np.empty((0,) + coords.shape)
        self._log_probs = np.empty((0, coords.shape[0]))
        self.accepted = np.zeros(coords.shape[0])
        self.steps = 0

    def _log_prob(self, coords: np.ndarray) -> tuple[np.ndarray, None]:
        values = np.asarray(self._batch(coords), float)
        if np.isnan(values).any():
            raise ValueError(f"the log posterior is NaN at {coords[np.isnan(values)][0].tolist()}")
        return values, None

    def run(self, steps: int) -> None:
        """Advance every walker by ``steps`` steps."""
        needed = self.steps + steps
        if needed > self._chain.shape[0]:
            capacity = max(needed, 2 * self._chain.shape[0])
            self._chain = _grown(self._chain, capacity)
            self._log_probs = _grown(self._log_probs, capacity)
        for _ in range(steps):
            move = self.moves[int(self._cumulative.searchsorted(self.random.random_sample(), side="right"))]
            self.state, accepted = move.propose(self._model, self.state)
            self._chain[self.steps] = self.state.coords
            self._log_probs[self.steps] = self.state.log_prob
            self.accepted += accepted
            self.steps += 1

    def get_chain(self) -> np.ndarray:
        """Every position so far, shape (steps, W, d) (a view: copy before the next run)."""
        return self._chain[: self.steps]

    def get_log_prob(self) -> np.ndarray:
        """The log posterior of :meth:`get_chain`, shape (steps, W)."""
        return self._log_probs[: self.steps]

    @property
    def acceptance_fraction(self) -> np.ndarray:
        """Accepted proposals per step, per walker."""
        return self.accepted / max(self.steps, 1)


def _grown(array: np.ndarray, rows: int) -> np.ndarray:
    out = np.empty((rows,) + array.shape[1:])
    out[: array.shape[0]] = array
    return out

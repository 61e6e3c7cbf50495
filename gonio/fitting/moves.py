"""emcee's stretch move with each half-ensemble evaluated and accepted at once.

Kept apart from :mod:`gonio.fitting.mcmc` so that reading a fit result (a report, a
comparison) does not import emcee, which loads scipy.stats.

References
----------
J. Goodman, J. Weare, "Ensemble samplers with affine invariance", Comm. App. Math. Comp.
Sci. 5(1), 65 (2010). D. Foreman-Mackey, D. W. Hogg, D. Lang, J. Goodman, "emcee: The
MCMC Hammer", PASP 125, 306 (2013).
"""
from __future__ import annotations

from typing import Callable

import emcee
import numpy as np

__all__ = ["VectorisedStretchMove"]


class VectorisedStretchMove(emcee.moves.StretchMove):
    """emcee's stretch move (Goodman & Weare 2010) with each half-ensemble's proposals
    evaluated and accepted in one vectorised step.

    Identical in distribution to :class:`emcee.moves.StretchMove`: the same proposal
    (``get_proposal`` is emcee's), the same acceptance probability
    min(1, z^(d-1) p(y)/p(x)), the same red-blue split.  Two loops over walkers that cost
    more than the model once the model itself is vectorised are done by numpy instead:
    the log posterior of the proposals comes straight from ``log_prob_batch`` (not through
    emcee's per-walker conversion of the results) and the acceptance test draws all its
    uniform numbers at once.

    Parameters
    ----------
    log_prob_batch : callable
        ``log_prob_batch(coords) -> ndarray``: log posterior of every row of ``coords``.
    a : float
        Stretch scale (emcee's default 2).
    """

    def __init__(self, log_prob_batch: Callable[[np.ndarray], np.ndarray], a: float = 2.0) -> None:
        super().__init__(a=a)
        self.log_prob_batch = log_prob_batch

    def propose(self, model, state):
        """One update of both halves of the ensemble; returns the new state and acceptances."""
        nwalkers = state.coords.shape[0]
        accepted = np.zeros(nwalkers, dtype=bool)
        halves = np.arange(nwalkers) % self.nsplits
        if self.randomize_split:
            model.random.shuffle(halves)
        for split in range(self.nsplits):
            moving = halves == split
            proposal, factors = self.get_proposal(state.coords[moving], [state.coords[~moving]], model.random)
            log_prob = np.asarray(self.log_prob_batch(proposal), float)
            gain = factors + log_prob - state.log_prob[moving]
            accepted[moving] = gain > np.log(model.random.rand(int(moving.sum())))
            state = self.update(state, emcee.State(proposal, log_prob=log_prob), accepted, moving)
        return state, accepted

"""BayesSim conditioning: the posterior given every real trajectory collected so far.

For i.i.d. real summaries x_1..x_n and a model trained on simulations from `proposal`,
p(theta | x_1..x_n) is proportional to p(theta) * prod_i q(theta | x_i) / proposal(theta)
(SNPE-A; the product of per-trajectory posteriors over p^(n-1) when the proposal is the prior).
correction.py computes it, in closed form where it exists; docs/statistics.md explains.
"""

from __future__ import annotations

import torch

from ...models.base import PosteriorModel
from .correction import posterior


def condition(model: PosteriorModel, x_obs: torch.Tensor, prior, max_components: int = 50, proposal=None,
              seed: int = 0):
    """The posterior given x_obs [n, F] (or one summary [F]), as a distribution with sample and log_prob.

    prior None means an improper flat prior (no truncation); proposal None means simulations from the prior.
    """
    x_obs = x_obs.reshape(-1, x_obs.shape[-1])
    conditionals = [model.conditional(x) for x in x_obs]
    return posterior(conditionals, prior, proposal, max_components=max_components, seed=seed)

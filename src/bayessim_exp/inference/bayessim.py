"""BayesSim conditioning: the posterior given every real trajectory collected so far.

With simulations drawn from the prior, q(theta | x) approximates p(theta | x). For i.i.d. real
trajectories x_1..x_n, p(theta | x_1..x_n) is proportional to prod_i p(theta | x_i) / p(theta)^(n-1):
for a uniform prior the divisor is constant inside the box, so the posterior is the product of
the per-trajectory mixtures (components pruned to `max_components`), truncated to the box.
"""

from __future__ import annotations

import torch

from ..errors import ConfigError
from ..models.base import PosteriorModel
from ..models.mixture import GaussianMixture, TruncatedMixture
from ..priors import BoxUniform


def combine(model: PosteriorModel, x_obs: torch.Tensor, max_components: int) -> GaussianMixture:
    """prod_i q(theta | x_i), renormalised, for summaries x_obs [n, F] (or one summary [F])."""
    x_obs = x_obs.reshape(-1, x_obs.shape[-1])
    combined = model.conditional(x_obs[0])
    for x in x_obs[1:]:
        combined = combined.product(model.conditional(x)).prune(max_components)
    return combined


def condition(model: PosteriorModel, x_obs: torch.Tensor, prior, max_components: int = 50):
    """The posterior given x_obs [n, F], as a distribution with sample and log_prob."""
    if prior is None:
        return combine(model, x_obs, max_components)
    if not isinstance(prior, BoxUniform):
        raise ConfigError(f"conditioning supports the uniform prior; got {type(prior).__name__}")
    return TruncatedMixture(combine(model, x_obs, max_components), prior.low, prior.high)

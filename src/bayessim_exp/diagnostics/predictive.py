"""Posterior predictive check: do simulations at posterior draws look like the real trajectories?

Summaries simulated at `num` posterior draws and at `num` prior draws are compared with each real
summary: the distance is the root-mean-square over features of (x_sim - x_real) / s, with s the
per-feature spread of the prior-predictive summaries, averaged over simulations and real summaries.
A posterior that explains the real data gives a clearly smaller distance than the prior.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from ..models.base import column_scale


def predictive_distances(simulate_summaries: Callable[[torch.Tensor], torch.Tensor], x_real: torch.Tensor,
                         posterior, prior, num: int = 200, seed: int = 0) -> dict[str, float]:
    """{"posterior": d, "prior": d} (see the module docstring); simulate_summaries(theta [n, D]) -> x [m, F]
    may drop simulations that diverged."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        x_post = simulate_summaries(posterior.sample((num,)).double()).double()
        x_prior = simulate_summaries(prior.sample((num,)).double()).double()
    scale = column_scale(x_prior)
    x_real = x_real.double().reshape(-1, x_real.shape[-1])

    def distance(x_sim: torch.Tensor) -> float:
        z = (x_sim[:, None, :] - x_real[None]) / scale
        return float(z.pow(2).mean(-1).sqrt().mean())

    return {"posterior": distance(x_post), "prior": distance(x_prior)}

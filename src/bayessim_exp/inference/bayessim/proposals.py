"""Next-round proposals built from a posterior (docs/statistics.md): the prior, the posterior itself,
its moment-matched Gaussian (SNPE-A in closed form), or the prior truncated to its HPD region (TSNPE)."""

from __future__ import annotations

import torch

from ...distributions.mixture import GaussianMixture, TruncatedMixture


def moment_matched(posterior, low: torch.Tensor | None = None, high: torch.Tensor | None = None,
                   num: int = 20_000, seed: int = 0):
    """A single Gaussian with the posterior's mean and covariance, truncated to [low, high] when given
    (the prior's box: simulated parameters must stay in range).

    As the next round's proposal it keeps the SNPE-A correction of mixture models in closed form.
    """
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        draws = posterior.sample((num,)).double()
    cov = torch.cov(draws.T).reshape(draws.shape[1], draws.shape[1])
    cov = cov + 1e-9 * cov.diagonal().mean() * torch.eye(cov.shape[0], dtype=cov.dtype)
    gaussian = GaussianMixture(torch.zeros(1), draws.mean(0, keepdim=True), cov[None])
    return gaussian if low is None else TruncatedMixture(gaussian, low, high, seed=seed)

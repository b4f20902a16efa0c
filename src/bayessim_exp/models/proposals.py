"""Next-round proposals built from a posterior.

Truncated proposals (TSNPE, Deistler et al. 2022): the prior restricted to a previous posterior's
highest-density region. On that region prior / proposal is constant, so a model trained on its draws needs no proposal
correction: q(theta | x) restricted to the prior's support is the posterior, provided the region
holds (nearly) all of the posterior's mass, which `hpd_mass` sets.
"""

from __future__ import annotations

import math

import torch

from .mixture import GaussianMixture, TruncatedMixture
from .rejection import sample_by_rejection


class TruncatedPrior:
    """prior(theta) * 1[posterior.log_prob(theta) >= threshold] / mass, sampled by rejection from the prior."""

    def __init__(self, prior, posterior, hpd_mass: float = 0.999, num: int = 20_000, seed: int = 0,
                 min_accept: float = 1e-3):
        if not 0.0 < hpd_mass < 1.0:
            raise ValueError(f"hpd_mass must be in (0, 1), got {hpd_mass}")
        self.prior, self.posterior = prior, posterior
        self.low, self.high = getattr(prior, "low", None), getattr(prior, "high", None)
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            lp = posterior.log_prob(posterior.sample((num,)).double())
            self.threshold = float(torch.quantile(lp[torch.isfinite(lp)], 1.0 - hpd_mass))
            accept = self._in_region(prior.sample((num,)).double()).double().mean()
        if accept < min_accept:
            # in many dimensions a concentrated posterior's region holds a vanishing share of the
            # prior: rejection from the prior would never finish
            raise ValueError(f"the previous posterior's {hpd_mass:.1%} region holds {float(accept):.2g} of the prior's "
                             f"mass (< {min_accept:g}): too little to sample by rejection")
        self.accept_rate = float(accept)

    def _in_region(self, theta: torch.Tensor) -> torch.Tensor:
        return self.posterior.log_prob(theta) >= self.threshold

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        lp = self.prior.log_prob(theta).double() - math.log(self.accept_rate)
        return torch.where(self._in_region(theta), lp, torch.tensor(-torch.inf, dtype=lp.dtype))

    def sample(self, shape: tuple[int, ...] = (1,)) -> torch.Tensor:
        n = math.prod(shape)
        draws = sample_by_rejection(lambda b: self.prior.sample((b,)).double(), self._in_region, n, self.accept_rate)
        return draws.reshape(*shape, -1)


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

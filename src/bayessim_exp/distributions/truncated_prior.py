"""The prior restricted to a previous posterior's highest-density region (TSNPE's truncated proposal).

Deistler et al. 2022: on that region prior / proposal is constant, so a model trained on its draws
needs no proposal correction: q(theta | x) restricted to the prior's support is the posterior,
provided the region holds (nearly) all of the posterior's mass, which `hpd_mass` sets.
"""

from __future__ import annotations

import math

import torch

from .base import ParameterDistribution
from .rejection import sample_by_rejection


class TruncatedPrior(ParameterDistribution):
    """prior(theta) * 1[posterior.log_prob(theta) >= threshold] / mass, sampled by rejection from the prior."""

    def __init__(self, prior, posterior, hpd_mass: float = 0.999, num: int = 20_000, seed: int = 0,
                 min_accept: float = 1e-3):
        if not 0.0 < hpd_mass < 1.0:
            raise ValueError(f"hpd_mass must be in (0, 1), got {hpd_mass}")
        self.prior, self.posterior = prior, posterior
        self.low, self.high = prior.low, prior.high
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

    @property
    def dim(self) -> int:
        return self.prior.dim

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        draws = sample_by_rejection(lambda b: self.prior.sample((b,), generator=generator).double(), self._in_region,
                                    n, self.accept_rate)
        return draws.reshape(*shape, -1)

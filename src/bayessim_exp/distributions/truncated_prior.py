"""The prior restricted to a previous posterior's highest-density region (TSNPE's truncated proposal).

Deistler et al. 2022: on that region prior / proposal is constant, so a model trained on its draws
needs no proposal correction: q(theta | x) restricted to the prior's support is the posterior,
provided the region holds (nearly) all of the posterior's mass, which `hpd_mass` sets.

Sampling is by rejection. Where the posterior is a Gaussian mixture (in probit space, or truncated
to the prior's box) the candidates come from the prior restricted to a box that provably holds the
region (`GaussianMixture.superlevel_box`): a concentrated posterior's region may hold a thousandth
of the prior and a good share of that box. Otherwise they come from the whole prior.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from .base import ParameterDistribution
from .mixture import GaussianMixture, TruncatedMixture
from .probit import ProbitPosterior, ProbitTransform
from .rejection import sample_by_rejection

# the candidates' box is widened by this much (relative) so that rounding never cuts off the region's rim
_BOX_MARGIN = 1e-9


class TruncatedPrior(ParameterDistribution):
    """prior(theta) * 1[posterior.log_prob(theta) >= threshold] / mass.

    mass, the region's prior mass, is the candidates' box's (exact) times the share of `num`
    candidates inside the region, the acceptance of the rejection sampler.
    """

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
            box_mass, self._candidates = _candidates(prior, posterior, self.threshold)
            self.acceptance = float(self._in_region(self._candidates(num)).double().mean())
        if self.acceptance < min_accept:
            # in many dimensions a concentrated posterior's region holds a vanishing share of the
            # candidates (the prior, where no box bounds it): rejection would never finish
            raise ValueError(f"the previous posterior's {hpd_mass:.1%} region holds {self.acceptance:.2g} of the "
                             f"candidates' mass (< {min_accept:g}): too little to sample by rejection")
        self.mass = box_mass * self.acceptance

    def _in_region(self, theta: torch.Tensor) -> torch.Tensor:
        return self.posterior.log_prob(theta) >= self.threshold

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        lp = self.prior.log_prob(theta).double() - math.log(self.mass)
        return torch.where(self._in_region(theta), lp, torch.tensor(-torch.inf, dtype=lp.dtype))

    @property
    def dim(self) -> int:
        return self.prior.dim

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        draws = sample_by_rejection(lambda b: self._candidates(b, generator), self._in_region, n, self.acceptance)
        return draws.reshape(*shape, -1)


def _candidates(prior, posterior, threshold: float) -> tuple[float, Callable[..., torch.Tensor]]:
    """(prior mass, sample(n, generator)) of the prior restricted to a box holding
    {theta: posterior.log_prob(theta) >= threshold}; the whole prior where no box is known."""
    box = _region_box(posterior, threshold)
    try:
        transform = ProbitTransform(prior)
    except ValueError:
        box = None
    if box is None:
        return 1.0, lambda n, generator=None: prior.sample((n,), generator=generator).double()
    low_u, high_u = (transform.to_probit(bound) for bound in box)  # clamped into the prior's box
    margin = _BOX_MARGIN * (1 + torch.maximum(low_u.abs(), high_u.abs()))
    return transform.prior_between(low_u - margin, high_u + margin)


def _region_box(posterior, threshold: float) -> tuple[torch.Tensor, torch.Tensor] | None:
    """A box in parameter units holding {theta: posterior.log_prob(theta) >= threshold}, where the
    posterior is a Gaussian mixture mapped from probit space or truncated to a box; else None."""
    if isinstance(posterior, ProbitPosterior) and isinstance(posterior.inner, GaussianMixture):
        # log posterior = log q_u(u) - log N(u; 0, I) + log prior(theta) <= that + the prior's peak
        transform = posterior.transform
        box = posterior.inner.superlevel_box(threshold - transform.log_prior_peak(), over_standard_normal=True)
        return None if box is None else tuple(transform.from_probit(bound) for bound in box)  # monotone per coordinate
    if isinstance(posterior, TruncatedMixture):
        return posterior.mixture.superlevel_box(threshold + posterior.log_mass_inside)
    return None

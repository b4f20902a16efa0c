"""The prior restricted to a previous posterior's highest-density region (TSNPE's truncated proposal).

Deistler et al. 2022: on that region prior / proposal is constant, so a model trained on its draws
needs no proposal correction: q(theta | x) restricted to the prior's support is the posterior,
provided the region holds (nearly) all of the posterior's mass, which `hpd_mass` sets.

Sampling is by rejection. Where the posterior knows a box that holds the region (its
`superlevel_box`: Gaussian mixtures, in probit space or truncated to the prior's box) the candidates
come from the prior restricted to that box: Pendulum's round-3 region holds 1 % of the prior and half
of the box. Otherwise they come from the whole prior.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from ..data_files import data_class, same_data
from .base import ParameterDistribution
from .probit import ProbitTransform
from .rejection import sample_by_rejection

# the candidates' box is widened by this much (relative) so that rounding never cuts off the region's rim
_BOX_MARGIN = 1e-9


@data_class
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

    def to_state(self) -> dict:  # the candidates' sampler is a closure: rebuilt from the rest
        return {k: v for k, v in vars(self).items() if k != "_candidates"}

    @classmethod
    def from_state(cls, fields: dict) -> TruncatedPrior:
        obj = cls.__new__(cls)
        obj.__dict__.update(fields)
        obj._candidates = _candidates(obj.prior, obj.posterior, obj.threshold)[1]
        return obj

    def restricts(self, prior: ParameterDistribution) -> bool:
        return self.prior is prior or same_data(self.prior, prior)  # the prior, or its copy read from an artifact

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
    box = posterior.superlevel_box(threshold) if isinstance(posterior, ParameterDistribution) else None
    try:
        transform = ProbitTransform(prior)
    except ValueError:
        box = None
    if box is None:
        return 1.0, lambda n, generator=None: prior.sample((n,), generator=generator).double()
    low_u, high_u = (transform.to_probit(bound) for bound in box)  # clamped into the prior's box
    margin = _BOX_MARGIN * (1 + torch.maximum(low_u.abs(), high_u.abs()))
    return transform.prior_between(low_u - margin, high_u + margin)

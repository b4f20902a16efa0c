"""The prior restricted to a previous posterior's highest-density region (TSNPE's truncated proposal).

Deistler et al. 2022: on that region prior / proposal is constant, so a model trained on its draws
needs no proposal correction: q(theta | x) restricted to the prior's support is the posterior,
provided the region holds (nearly) all of the posterior's mass, which `hpd_mass` sets.

Sampling is by rejection from candidates that cover the region:
- a posterior that is a Gaussian mixture in probit space (every mixture model's, by default): the prior tilted
  towards each component (relaxed_cover.py), exact in any number of parameters (ShadowHand's 30: about a tenth of
  the candidates kept where the prior restricted to a box around the region kept 1e-3);
- a Gaussian mixture truncated to the prior's box (method.parameter_space=box): the prior restricted to a box
  holding the region (its `superlevel_box`): Pendulum's round-3 region holds 1 % of the prior and half of the box;
- otherwise (flows, importance-sampled posteriors) the whole prior.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from ..data_files import data_class, same_data
from .base import ParameterDistribution
from .mixture import GaussianMixture
from .probit import ProbitTransform
from .rejection import sample_by_rejection
from .relaxed_cover import RelaxedCover

# the candidates' box is widened by this much (relative) so that rounding never cuts off the region's rim
_BOX_MARGIN = 1e-9


@data_class
class TruncatedPrior(ParameterDistribution):
    """prior(theta) * 1[posterior.log_prob(theta) >= threshold] / mass.

    mass, the region's prior mass, is the candidates' scale (exact: a box's prior mass, or relaxed_cover's bound)
    times the share of `num` candidates kept, the acceptance of the rejection sampler.
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
            log_scale, self._candidates = _candidates(prior, posterior, self.threshold)
            self.acceptance = float(self._in_region(self._candidates(num)).sum()) / num
        if self.acceptance < min_accept:
            # a region the candidates miss (a posterior without a mixture form whose region holds a vanishing
            # share of the prior): rejection would never finish
            raise ValueError(f"the previous posterior's {hpd_mass:.1%} region holds {self.acceptance:.2g} of the "
                             f"candidates' mass (< {min_accept:g}): too little to sample by rejection")
        self.log_mass = log_scale + math.log(self.acceptance)

    @property
    def mass(self) -> float:
        return math.exp(self.log_mass)

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
        lp = self.prior.log_prob(theta).double() - self.log_mass
        return torch.where(self._in_region(theta), lp, torch.tensor(-torch.inf, dtype=lp.dtype))

    @property
    def dim(self) -> int:
        return self.prior.dim

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        """Draws whose float32 roundings lie in the region too: the pipeline stores simulated parameters in float32,
        and in many dimensions most of the region's prior mass lies at its rim, where rounding moved 4 % of
        Cartpole's and FrankaCabinet's draws out of it (their proposal density zero, the held-out gain over the
        proposal not a number)."""
        n = math.prod(shape)
        draws = sample_by_rejection(lambda b: self._candidates(b, generator).float().double(), self._in_region, n,
                                    self.acceptance)
        return draws.reshape(*shape, -1)


def _candidates(prior, posterior, threshold: float) -> tuple[float, Callable[..., torch.Tensor]]:
    """(log scale, sample(n, generator)): candidates of which those inside {posterior.log_prob >= threshold} are
    the prior restricted to it, their share times the scale its prior mass; sample returns at most n of them."""
    try:
        transform = ProbitTransform(prior)
    except ValueError:
        transform = None
    inner = posterior.in_probit_space() if isinstance(posterior, ParameterDistribution) else None
    if transform is not None and isinstance(inner, GaussianMixture):
        # the region lies in {log q_u - log N(u; 0, I) >= threshold - the prior's peak log density} (probit.py)
        cover = RelaxedCover(inner, threshold - transform.log_prior_peak())
        return cover.log_bound, lambda n, generator=None: transform.from_probit(cover.draw(n, generator))
    box = posterior.superlevel_box(threshold) if isinstance(posterior, ParameterDistribution) else None
    if box is None or transform is None:
        return 0.0, lambda n, generator=None: prior.sample((n,), generator=generator).double()
    low_u, high_u = (transform.to_probit(bound) for bound in box)  # clamped into the prior's box
    margin = _BOX_MARGIN * (1 + torch.maximum(low_u.abs(), high_u.abs()))
    mass, sample = transform.prior_between(low_u - margin, high_u + margin)
    return math.log(mass), sample

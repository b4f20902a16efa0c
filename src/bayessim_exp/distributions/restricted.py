"""Any distribution restricted to a box and renormalised (flows' posteriors on the prior's support)."""

from __future__ import annotations

import math

import torch

from ..data_files import data_class
from .base import ParameterDistribution, seeded_by
from .box import inside, restrict_log_prob
from .rejection import sample_by_rejection


@data_class
class Restricted(ParameterDistribution):
    """dist restricted to [low, high]; the mass inside is a Monte Carlo estimate from `num_mc` draws,
    sampling is exact by rejection."""

    def __init__(self, dist, low: torch.Tensor, high: torch.Tensor, num_mc: int = 50_000, seed: int = 0,
                 min_hits: int = 50):
        self.dist, self.low, self.high = dist, low.double(), high.double()
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            hits = int(inside(dist.sample((num_mc,)).double(), self.low, self.high).sum())
        if hits < min_hits:
            # rejection would need about num_mc / hits draws per sample: refuse rather than exhaust memory
            raise ValueError(f"the posterior puts {hits} of {num_mc} draws inside the prior's support (fewer than "
                             f"{min_hits}); the model is badly fitted or, for a flow with many parameters, use "
                             "model=mdnn, whose mixtures are truncated in closed form")
        self.mass_inside = hits / num_mc
        self._log_mass = math.log(self.mass_inside)

    @property
    def dim(self) -> int:
        return self.low.shape[0]

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        return restrict_log_prob(self.dist.log_prob(theta).double() - self._log_mass, theta, self.low, self.high)

    @torch.no_grad()
    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        with seeded_by(generator):  # `dist` may be any distribution, one that takes no generator too
            draws = sample_by_rejection(lambda b: self.dist.sample((b,)).double(),
                                        lambda t: inside(t, self.low, self.high), n, self.mass_inside)
        return draws.reshape(*shape, self.dim)

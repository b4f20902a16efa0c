"""Posteriors known up to a constant: importance weights against a base distribution.

The sound fallback when a proposal correction has no closed form: the target density
log p(theta) + sum_i [log q(theta | x_i) - log p~(theta)] is evaluated exactly, its normaliser is
estimated by importance sampling from a base that covers it, and samples come from
sampling-importance-resampling over a fixed pool of base draws.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from ..data_files import data_class
from .base import ParameterDistribution


def _draw(dist, num: int, seed: int) -> torch.Tensor:
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return dist.sample((num,)).double()


@data_class
class ImportancePosterior(ParameterDistribution):
    """exp(log_target(theta)) / Z with Z estimated from `num` draws of `base`.

    `ess` (effective sample size of the pool) says how well the base covers the target: the
    normaliser's relative error is roughly 1 / sqrt(ess).
    """

    def __init__(self, log_target: Callable[[torch.Tensor], torch.Tensor], base, num: int = 100_000, seed: int = 0):
        self.log_target = log_target
        pool = _draw(base, num, seed)
        log_w = log_target(pool) - base.log_prob(pool).double()
        log_w = torch.where(torch.isnan(log_w), torch.tensor(-torch.inf, dtype=log_w.dtype), log_w)
        if not torch.isfinite(log_w).any():
            raise ValueError("importance sampling found no base draw where the target has mass")
        self.log_norm = float(torch.logsumexp(log_w, 0) - math.log(num))
        self._weights = torch.softmax(log_w, 0)
        self.ess = float(1.0 / (self._weights**2).sum())
        self._pool = pool
        self._generator = torch.Generator().manual_seed(seed + 1)

    @property
    def dim(self) -> int:
        return self._pool.shape[1]

    @property
    def effective_sample_size(self) -> float:
        return self.ess

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        return self.log_target(theta.double()) - self.log_norm

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        idx = torch.multinomial(self._weights, n, replacement=True, generator=generator or self._generator)
        return self._pool[idx].reshape(*shape, self.dim)

    @property
    def mean(self) -> torch.Tensor:
        """Self-normalised importance estimate over the pool."""
        return (self._weights[:, None] * self._pool).sum(0)

    @property
    def stddev(self) -> torch.Tensor:
        return (self._weights[:, None] * (self._pool - self.mean) ** 2).sum(0).sqrt()


@data_class
class DefensiveMixture(ParameterDistribution):
    """An equal-weight mixture of arbitrary distributions: an importance base whose tails cover each part's."""

    def __init__(self, parts: list):
        self.parts = parts

    @property
    def dim(self) -> int:
        return self.parts[0].dim

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        which = torch.randint(len(self.parts), (n,), generator=generator)
        out = torch.empty(n, self.dim, dtype=torch.float64)
        for j, part in enumerate(self.parts):
            mask = which == j
            if mask.any():
                out[mask] = part.sample((int(mask.sum()),), generator=generator).double()
        return out.reshape(*shape, out.shape[-1])

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        lps = torch.stack([p.log_prob(theta).double() for p in self.parts], -1)
        return torch.logsumexp(lps, -1) - math.log(len(self.parts))

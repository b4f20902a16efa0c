"""Any ParameterDistribution as a torch.distributions.Distribution, for code written against torch's interface
(sbi's process_prior and its inference classes, Pyro, a domain-randomization stack that samples a torch prior).

The view has event_shape [D] and an empty batch shape, its support is the distribution's box (real numbers where it
has none), and it samples and scores in float32 by default: sbi wants float32 and wraps (with warnings) whatever
is not a torch Distribution of that dtype. Sampling without a generator draws from torch's global generator, so
torch.manual_seed makes it reproducible, as for torch's own distributions. Values outside the support score -inf
(validate_args=True raises instead, as torch's distributions do).
"""

from __future__ import annotations

import math

import torch
from torch.distributions import Distribution, constraints

from .base import ParameterDistribution


class TorchDistribution(Distribution):
    arg_constraints: dict = {}
    has_rsample = False

    def __init__(self, dist: ParameterDistribution, names: list[str] | None = None,
                 dtype: torch.dtype = torch.float32, validate_args: bool = False):
        if names is not None and len(names) != dist.dim:
            raise ValueError(f"{len(names)} names for a distribution over {dist.dim} parameters")
        self.dist, self.names, self.dtype = dist, list(names) if names is not None else None, dtype
        super().__init__(torch.Size(), torch.Size([dist.dim]), validate_args=validate_args)

    @constraints.dependent_property(is_discrete=False, event_dim=1)
    def support(self) -> constraints.Constraint:
        if self.dist.low is None or self.dist.high is None:
            return constraints.independent(constraints.real, 1)
        return constraints.independent(constraints.interval(self.dist.low.to(self.dtype),
                                                            self.dist.high.to(self.dtype)), 1)

    def sample(self, sample_shape: torch.Size | tuple[int, ...] = ()) -> torch.Tensor:
        shape = torch.Size(sample_shape)
        n = math.prod(shape)
        if n == 0:
            return torch.empty(shape + self.event_shape, dtype=self.dtype)
        # a generator seeded from torch's global one: distributions that keep a generator of their own ignore the latter
        generator = torch.Generator().manual_seed(int(torch.randint(0, 2**62, (1,))))
        with torch.no_grad():
            draws = self.dist.sample((n,), generator=generator)
        return draws.reshape(shape + self.event_shape).to(self.dtype)

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        value = torch.as_tensor(value)
        if self._validate_args:
            self._validate_sample(value)
        flat = value.reshape(-1, self.dist.dim).to(torch.float64)
        return self.dist.log_prob(flat).reshape(value.shape[:-1]).to(self.dtype)

    @property
    def mean(self) -> torch.Tensor:
        return self.dist.mean.to(self.dtype)

    @property
    def stddev(self) -> torch.Tensor:
        return self.dist.stddev.to(self.dtype)

    @property
    def variance(self) -> torch.Tensor:
        return self.stddev.pow(2)

    def __repr__(self) -> str:
        names = f", names={self.names}" if self.names else ""
        return f"TorchDistribution({type(self.dist).__name__} over {self.dist.dim} parameters{names})"

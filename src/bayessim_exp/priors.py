"""Priors over the task's parameters; their support is the ParamSpec's box."""

from __future__ import annotations

import dataclasses

import torch
from torch.distributions import Distribution, Independent, Uniform

from .registry import register
from .sim.params import ParamSpec


@dataclasses.dataclass
class UniformPriorConfig:
    pass


class BoxUniform(Independent):
    """Uniform over [low, high]^D, with the box exposed as `low`/`high` for truncation."""

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        super().__init__(Uniform(low, high, validate_args=False), 1, validate_args=False)
        self.low, self.high = low, high

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        inside = ((value >= self.low) & (value <= self.high)).all(-1)
        lp = -torch.log(self.high - self.low).sum()
        return torch.where(inside, lp, torch.tensor(-torch.inf, dtype=lp.dtype))


@register("prior", "uniform", UniformPriorConfig)
def uniform_prior(cfg: UniformPriorConfig, spec: ParamSpec) -> Distribution:
    return BoxUniform(torch.as_tensor(spec.low, dtype=torch.float64), torch.as_tensor(spec.high, dtype=torch.float64))

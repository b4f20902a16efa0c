"""The prior config group: priors over a task's parameters, on the ParamSpec's box (distributions/independent.py)."""

from __future__ import annotations

import dataclasses
import math

import torch

from .distributions.base import ParameterDistribution
from .distributions.independent import BoxUniform, GaussianPrior, LogUniform
from .errors import ConfigError
from .tasks.params import ParamSpec


def _box(spec: ParamSpec) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.as_tensor(spec.low, dtype=torch.float64), torch.as_tensor(spec.high, dtype=torch.float64)


@dataclasses.dataclass
class UniformPriorConfig:
    pass


def uniform_prior(cfg: UniformPriorConfig, spec: ParamSpec) -> ParameterDistribution:
    return BoxUniform(*_box(spec))


@dataclasses.dataclass
class LogUniformPriorConfig:
    pass


def loguniform_prior(cfg: LogUniformPriorConfig, spec: ParamSpec) -> ParameterDistribution:
    low, high = _box(spec)
    if (low <= 0).any():
        bad = [n for n, lo in zip(spec.names, spec.low) if lo <= 0]
        raise ConfigError(f"prior=loguniform needs positive ranges; not positive: {', '.join(bad)}")
    return LogUniform(low, high)


@dataclasses.dataclass
class GaussianPriorConfig:
    stds_per_range: float  # the range [low, high] spans this many standard deviations around its midpoint
    truncate: bool  # restrict to the range (simulated parameters must stay physical)

    def validate(self) -> None:
        if not self.stds_per_range > 0 or not math.isfinite(self.stds_per_range):
            raise ConfigError(f"stds_per_range must be a positive number, got {self.stds_per_range}")


def gaussian_prior(cfg: GaussianPriorConfig, spec: ParamSpec) -> ParameterDistribution:
    low, high = _box(spec)
    mean, std = 0.5 * (low + high), (high - low) / cfg.stds_per_range
    return GaussianPrior(mean, std, low, high) if cfg.truncate else GaussianPrior(mean, std)

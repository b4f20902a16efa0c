"""Priors over the task's parameters; their support is the ParamSpec's box.

Every bounded prior exposes the box as `low`/`high` so that posteriors can be truncated to it;
`GaussianPrior` also exposes `loc`/`scale` (of the untruncated Gaussian), which the SNPE-A correction uses in closed form.
"""

from __future__ import annotations

import dataclasses
import math

import torch
from torch.distributions import Distribution, Independent, Normal, Uniform

from .errors import ConfigError
from .registry import register
from .sim.params import ParamSpec


def _inside(value: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    return ((value >= low) & (value <= high)).all(-1)


class BoxUniform(Independent):
    """Uniform over [low, high]^D, with the box exposed as `low`/`high` for truncation."""

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        super().__init__(Uniform(low, high, validate_args=False), 1, validate_args=False)
        self.low, self.high = low, high

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        lp = -torch.log(self.high - self.low).sum()
        return torch.where(_inside(value, self.low, self.high), lp, torch.tensor(-torch.inf, dtype=lp.dtype))


class LogUniform(Distribution):
    """log(theta) uniform over [log low, log high] per parameter (scale parameters: masses, gains)."""

    arg_constraints: dict = {}

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        self.low, self.high = low.double(), high.double()
        self._log_low, self._log_high = self.low.log(), self.high.log()
        super().__init__(event_shape=self.low.shape, validate_args=False)

    @property
    def mean(self) -> torch.Tensor:
        return (self.high - self.low) / (self._log_high - self._log_low)

    @property
    def variance(self) -> torch.Tensor:
        second = (self.high**2 - self.low**2) / (2 * (self._log_high - self._log_low))
        return second - self.mean**2

    def sample(self, sample_shape=torch.Size()) -> torch.Tensor:
        u = torch.rand(*sample_shape, *self.low.shape, dtype=torch.float64)
        return torch.exp(self._log_low + u * (self._log_high - self._log_low))

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        value = value.double()
        inside = _inside(value, self.low, self.high)
        lp = -(torch.log(value.clamp_min(1e-300)) + torch.log(self._log_high - self._log_low)).sum(-1)
        return torch.where(inside, lp, torch.tensor(-torch.inf, dtype=lp.dtype))


class GaussianPrior(Distribution):
    """Independent Gaussians N(loc, scale^2), optionally truncated to the box [low, high].

    Truncation is exact: each coordinate is sampled by the inverse CDF restricted to its interval,
    and the density is renormalised by the product of the per-coordinate masses.
    """

    arg_constraints: dict = {}

    def __init__(self, mean: torch.Tensor, std: torch.Tensor,
                 low: torch.Tensor | None = None, high: torch.Tensor | None = None):
        self.loc, self.scale = mean.double(), std.double()
        self.low = None if low is None else low.double()
        self.high = None if high is None else high.double()
        self._normal = Normal(self.loc, self.scale, validate_args=False)
        if self.low is not None:
            self._cdf_low = self._normal.cdf(self.low)
            self._cdf_high = self._normal.cdf(self.high)
            self._log_mass = torch.log(self._cdf_high - self._cdf_low).sum()
        super().__init__(event_shape=self.loc.shape, validate_args=False)

    @property
    def covariance_matrix(self) -> torch.Tensor:
        """Of the untruncated Gaussian."""
        return torch.diag(self.scale**2)

    @property
    def mean(self) -> torch.Tensor:
        if self.low is None:
            return self.loc
        return self.loc + self.scale * self._truncation_terms()[0]

    @property
    def variance(self) -> torch.Tensor:
        if self.low is None:
            return self.scale**2
        shift, spread = self._truncation_terms()
        return self.scale**2 * (1 + spread - shift**2)

    def _truncation_terms(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Truncated-normal moments: mean = loc + scale * t1, var = scale^2 (1 + t2 - t1^2)."""
        a, b = (self.low - self.loc) / self.scale, (self.high - self.loc) / self.scale
        pdf = lambda z: torch.exp(-0.5 * z**2) / math.sqrt(2 * math.pi)  # noqa: E731
        mass = self._cdf_high - self._cdf_low
        return (pdf(a) - pdf(b)) / mass, (a * pdf(a) - b * pdf(b)) / mass

    def sample(self, sample_shape=torch.Size()) -> torch.Tensor:
        shape = (*sample_shape, *self.loc.shape)
        if self.low is None:
            return self.loc + self.scale * torch.randn(shape, dtype=torch.float64)
        u = self._cdf_low + torch.rand(shape, dtype=torch.float64) * (self._cdf_high - self._cdf_low)
        return (self.loc + self.scale * torch.special.ndtri(u)).clamp(self.low, self.high)

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        value = value.double()
        lp = self._normal.log_prob(value).sum(-1)
        if self.low is None:
            return lp
        return torch.where(_inside(value, self.low, self.high), lp - self._log_mass,
                           torch.tensor(-torch.inf, dtype=lp.dtype))


def _box(spec: ParamSpec) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.as_tensor(spec.low, dtype=torch.float64), torch.as_tensor(spec.high, dtype=torch.float64)


@dataclasses.dataclass
class UniformPriorConfig:
    pass


@register("prior", "uniform", UniformPriorConfig)
def uniform_prior(cfg: UniformPriorConfig, spec: ParamSpec) -> Distribution:
    return BoxUniform(*_box(spec))


@dataclasses.dataclass
class LogUniformPriorConfig:
    pass


@register("prior", "loguniform", LogUniformPriorConfig)
def loguniform_prior(cfg: LogUniformPriorConfig, spec: ParamSpec) -> Distribution:
    low, high = _box(spec)
    if (low <= 0).any():
        bad = [n for n, lo in zip(spec.names, spec.low) if lo <= 0]
        raise ConfigError(f"prior=loguniform needs positive ranges; not positive: {', '.join(bad)}")
    return LogUniform(low, high)


@dataclasses.dataclass
class GaussianPriorConfig:
    stds_per_range: float = 4.0  # the range [low, high] spans this many standard deviations around its midpoint
    truncate: bool = True  # restrict to the range (simulated parameters must stay physical)

    def validate(self) -> None:
        if not self.stds_per_range > 0 or not math.isfinite(self.stds_per_range):
            raise ConfigError(f"stds_per_range must be a positive number, got {self.stds_per_range}")


@register("prior", "gaussian", GaussianPriorConfig)
def gaussian_prior(cfg: GaussianPriorConfig, spec: ParamSpec) -> Distribution:
    low, high = _box(spec)
    mean, std = 0.5 * (low + high), (high - low) / cfg.stds_per_range
    return GaussianPrior(mean, std, low, high) if cfg.truncate else GaussianPrior(mean, std)

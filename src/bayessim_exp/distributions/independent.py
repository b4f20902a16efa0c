"""Independent per-parameter distributions: the priors (box uniform, log-uniform, Gaussian).

Bounded ones expose their box as `low`/`high`, the support posteriors are truncated to; each answers
its per-coordinate CDF, inverse CDF and log density (probit space, distributions/probit.py) and its
Gaussian factor (the SNPE-A correction in closed form: the untruncated Gaussian's, or none for a uniform).
"""

from __future__ import annotations

import math

import torch
from torch.special import ndtr, ndtri

from ..data_files import data_class
from .base import ParameterDistribution
from .box import restrict_log_prob

_LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


def std_normal_log_pdf(u: torch.Tensor) -> torch.Tensor:
    return -0.5 * u**2 - _LOG_SQRT_2PI


def _uniform(shape: tuple[int, ...], dim: int, generator: torch.Generator | None) -> torch.Tensor:
    return torch.rand(*shape, dim, dtype=torch.float64, generator=generator)


@data_class
class BoxUniform(ParameterDistribution):
    """Uniform over [low, high]^D."""

    independent = True

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        self.low, self.high = torch.as_tensor(low).double(), torch.as_tensor(high).double()

    def gaussian_factor(self) -> None:
        return None  # constant on the box

    def marginal_cdf(self, theta: torch.Tensor) -> torch.Tensor:
        return (theta - self.low) / (self.high - self.low)

    def marginal_icdf(self, c: torch.Tensor) -> torch.Tensor:
        return self.low + c * (self.high - self.low)

    def log_marginal(self, theta: torch.Tensor) -> torch.Tensor:
        return -torch.log(self.high - self.low).expand_as(theta)

    @property
    def peak(self) -> torch.Tensor:
        return self.low

    @property
    def dim(self) -> int:
        return self.low.shape[0]

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        return self.low + (self.high - self.low) * _uniform(tuple(shape), self.dim, generator)

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        lp = (-torch.log(self.high - self.low).sum()).expand(theta.shape[:-1])
        return restrict_log_prob(lp, theta, self.low, self.high)

    @property
    def mean(self) -> torch.Tensor:
        return 0.5 * (self.low + self.high)

    @property
    def stddev(self) -> torch.Tensor:
        return (self.high - self.low) / math.sqrt(12.0)


@data_class
class LogUniform(ParameterDistribution):
    """log(theta) uniform over [log low, log high] per parameter (scale parameters: masses, gains)."""

    independent = True

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        self.low, self.high = torch.as_tensor(low).double(), torch.as_tensor(high).double()
        self._log_low, self._log_high = self.low.log(), self.high.log()

    def marginal_cdf(self, theta: torch.Tensor) -> torch.Tensor:
        return (torch.log(theta) - self._log_low) / (self._log_high - self._log_low)

    def marginal_icdf(self, c: torch.Tensor) -> torch.Tensor:
        return torch.exp(self._log_low + c * (self._log_high - self._log_low))

    def log_marginal(self, theta: torch.Tensor) -> torch.Tensor:
        return -torch.log(theta) - torch.log(self._log_high - self._log_low)

    @property
    def peak(self) -> torch.Tensor:
        return self.low

    @property
    def dim(self) -> int:
        return self.low.shape[0]

    @property
    def mean(self) -> torch.Tensor:
        return (self.high - self.low) / (self._log_high - self._log_low)

    @property
    def stddev(self) -> torch.Tensor:
        second = (self.high**2 - self.low**2) / (2 * (self._log_high - self._log_low))
        return (second - self.mean**2).sqrt()

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        u = _uniform(tuple(shape), self.dim, generator)
        return torch.exp(self._log_low + u * (self._log_high - self._log_low))

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        lp = -(torch.log(theta.clamp_min(1e-300)) + torch.log(self._log_high - self._log_low)).sum(-1)
        return restrict_log_prob(lp, theta, self.low, self.high)


@data_class
class GaussianPrior(ParameterDistribution):
    """Independent Gaussians N(loc, scale^2), optionally truncated to the box [low, high].

    Truncation is exact: each coordinate is sampled by the inverse CDF restricted to its interval,
    and the density is renormalised by the product of the per-coordinate masses.
    """

    independent = True

    def __init__(self, mean: torch.Tensor, std: torch.Tensor,
                 low: torch.Tensor | None = None, high: torch.Tensor | None = None):
        self.loc, self.scale = torch.as_tensor(mean).double(), torch.as_tensor(std).double()
        self.low = None if low is None else torch.as_tensor(low).double()
        self.high = None if high is None else torch.as_tensor(high).double()
        if self.low is not None:
            self._cdf_low = ndtr((self.low - self.loc) / self.scale)
            self._cdf_high = ndtr((self.high - self.loc) / self.scale)
            self._log_mass = torch.log(self._cdf_high - self._cdf_low).sum()

    @property
    def dim(self) -> int:
        return self.loc.shape[0]

    @property
    def covariance_matrix(self) -> torch.Tensor:
        """Of the untruncated Gaussian."""
        return torch.diag(self.scale**2)

    def gaussian_factor(self) -> tuple[torch.Tensor, torch.Tensor]:
        return self.loc, self.covariance_matrix  # truncation only restricts the support

    def marginal_cdf(self, theta: torch.Tensor) -> torch.Tensor:
        cdf = ndtr((theta - self.loc) / self.scale)
        return cdf if self.low is None else (cdf - self._cdf_low) / (self._cdf_high - self._cdf_low)

    def marginal_icdf(self, c: torch.Tensor) -> torch.Tensor:
        if self.low is None:
            return self.loc + self.scale * ndtri(c)
        return self.loc + self.scale * ndtri(self._cdf_low + c * (self._cdf_high - self._cdf_low))

    def log_marginal(self, theta: torch.Tensor) -> torch.Tensor:
        lp = std_normal_log_pdf((theta - self.loc) / self.scale) - torch.log(self.scale)
        return lp if self.low is None else lp - torch.log(self._cdf_high - self._cdf_low)

    @property
    def peak(self) -> torch.Tensor:
        return self.loc if self.low is None else self.loc.clamp(self.low, self.high)

    @property
    def mean(self) -> torch.Tensor:
        if self.low is None:
            return self.loc
        return self.loc + self.scale * self._truncation_terms()[0]

    @property
    def stddev(self) -> torch.Tensor:
        if self.low is None:
            return self.scale
        shift, spread = self._truncation_terms()
        return self.scale * (1 + spread - shift**2).sqrt()

    def _truncation_terms(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Truncated-normal moments: mean = loc + scale * t1, var = scale^2 (1 + t2 - t1^2)."""
        a, b = (self.low - self.loc) / self.scale, (self.high - self.loc) / self.scale
        pdf = lambda z: torch.exp(-0.5 * z**2) / math.sqrt(2 * math.pi)  # noqa: E731
        mass = self._cdf_high - self._cdf_low
        return (pdf(a) - pdf(b)) / mass, (a * pdf(a) - b * pdf(b)) / mass

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        if self.low is None:
            return self.loc + self.scale * torch.randn(*shape, self.dim, dtype=torch.float64, generator=generator)
        u = self._cdf_low + _uniform(tuple(shape), self.dim, generator) * (self._cdf_high - self._cdf_low)
        return (self.loc + self.scale * ndtri(u)).clamp(self.low, self.high)

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        z = (theta - self.loc) / self.scale
        lp = (-0.5 * z**2 - torch.log(self.scale) - 0.5 * math.log(2 * math.pi)).sum(-1)
        if self.low is None:
            return lp
        return restrict_log_prob(lp - self._log_mass, theta, self.low, self.high)

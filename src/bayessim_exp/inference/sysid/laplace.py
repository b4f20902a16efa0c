"""A Gaussian over the parameters from a sysid fit: the Gauss-Newton likelihood around the estimate times a Gaussian
with the prior's mean and standard deviations, and the prior's spread for each parameter the data do not identify.

Gauss-Newton reads the least-squares fit as a Gaussian likelihood: residuals r(u) ~ N(0, s^2 I), so near the
estimate u* the log likelihood is -(u - u*)^T (J^T J / s^2) (u - u*) / 2, J the residuals' Jacobian at u*. sysid's
covariance s^2 (J^T J)^-1 is its inverse, infinite along directions the data do not move. Adding the prior's
precision, with the prior's mean m0 and standard deviations as a Gaussian N(m0, V0) (V0 diagonal), keeps it finite:

    precision P = J^T J / s^2 + V0^-1,    mean = P^-1 (J^T J / s^2 u* + V0^-1 m0).

That is the estimate and sysid's covariance where the data pin the parameters down, and the prior's mean and spread
for a parameter no observation depends on. It is not enough where the data leave a curved set of parameters that
all fit (Cartpole: masses, dampings, frictions and the motor gain scaled together; the rod's and tip's masses
against the pole's length): the linearised likelihood is a thin slab along the set's tangent at u*, and parameters
elsewhere on the set, the truth among them, lie far outside it. So a parameter whose standard deviation from the
data alone, sysid's s sqrt((J^T J)^-1_ii), is not below `identified_below` times the prior's is taken as not
identified: it keeps the prior's standard deviation, uncorrelated with the others, and its mean from P. The
identified ones keep their block of P^-1, the uncertainty of the others integrated out.

s^2 is sysid's estimate |r(u*)|^2 / (R - D), floored at min_noise_std^2: on data without noise (a surrogate 'real'
system that is the simulator itself) the residual left at the estimate is float32 rounding and finite-difference
error, and intervals that narrow say nothing about the parameters. All of this is in the unit coordinates of the
prior box (residual.py) and mapped back to the parameters' units at the end.
"""

from __future__ import annotations

import dataclasses
import math

import torch

from ...errors import PosteriorError
from .fit import SysidFit


@dataclasses.dataclass(frozen=True)
class LaplaceGaussian:
    mean: torch.Tensor  # [D], parameter units
    cov: torch.Tensor  # [D, D]
    noise_std: float  # s, as used (after the floor), in units of each observation's spread
    data_std: torch.Tensor  # [D], parameter units: sysid's standard deviations at s (inf: not identifiable)
    identified: torch.Tensor  # [D] bool


def laplace_gaussian(result: SysidFit, prior_mean: torch.Tensor, prior_std: torch.Tensor, low: torch.Tensor,
                     high: torch.Tensor, min_noise_std: float, identified_below: float) -> LaplaceGaussian:
    low, span = low.double(), (high - low).double()
    noise_var = max(result.noise_var, min_noise_std**2)
    jac = torch.as_tensor(result.jacobian, dtype=torch.float64)
    information = jac.T @ jac / noise_var
    prior_var = (prior_std.double() / span) ** 2  # V0 in unit coordinates
    precision = information + torch.diag(1.0 / prior_var)
    factor, info = torch.linalg.cholesky_ex(0.5 * (precision + precision.T))
    if info != 0:
        raise PosteriorError(f"sysid's precision is too ill-conditioned to invert at noise {math.sqrt(noise_var):.3g}; "
                             "raise method.min_noise_std")
    cov = torch.cholesky_inverse(factor)
    m0 = (prior_mean.double() - low) / span
    mean = cov @ (information @ torch.as_tensor(result.estimate, dtype=torch.float64) + m0 / prior_var)
    data_std = torch.as_tensor(result.unit_noise_std, dtype=torch.float64) * math.sqrt(noise_var)
    identified = data_std < identified_below * prior_var.sqrt()
    free = ~identified
    cov[free, :] = 0.0
    cov[:, free] = 0.0
    cov[free, free] = prior_var[free]
    cov = 0.5 * (cov + cov.T) * span[:, None] * span[None, :]
    return LaplaceGaussian(low + span * mean, cov, math.sqrt(noise_var), data_std * span, identified)

"""A Gaussian over the parameters from a sysid fit: the Gauss-Newton likelihood around the estimate times a Gaussian
with the prior's mean and standard deviations.

Gauss-Newton reads the least-squares fit as a Gaussian likelihood: residuals r(u) ~ N(0, s^2 I), so near the
estimate u* the log likelihood is -(u - u*)^T (J^T J / s^2) (u - u*) / 2, J the residuals' Jacobian at u*. sysid's
covariance s^2 (J^T J)^-1 is its inverse and is infinite along directions the data do not move (a parameter that
changes no observation; masses, dampings and gains scaled together). Adding the prior's precision, with the
prior's mean m0 and standard deviations as a Gaussian N(m0, V0) (V0 diagonal), keeps those directions finite:

    precision P = J^T J / s^2 + V0^-1,    mean = P^-1 (J^T J / s^2 u* + V0^-1 m0),

which is the estimate and sysid's covariance wherever the data pin the parameters down, and the prior's mean and
spread for a parameter they say nothing about. The product is the posterior of the linearised model under that
Gaussian stand-in for the prior; the pipeline restricts it to the prior's box.

s^2 is sysid's estimate |r(u*)|^2 / (R - D), floored at min_noise_std^2: on data without noise (a surrogate 'real'
system that is the simulator itself) the residual left at the estimate is float32 rounding and finite-difference
error, and intervals that narrow say nothing about the parameters. All of this is in the unit coordinates of
the prior box (residual.py) and mapped back to the parameters' units at the end.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from .fit import SysidFit


@dataclasses.dataclass(frozen=True)
class LaplaceGaussian:
    mean: torch.Tensor  # [D], parameter units
    cov: torch.Tensor  # [D, D]
    noise_std: float  # s, as used (after the floor), in units of each observation's spread


def laplace_gaussian(result: SysidFit, prior_mean: torch.Tensor, prior_std: torch.Tensor, low: torch.Tensor,
                     high: torch.Tensor, min_noise_std: float) -> LaplaceGaussian:
    low, span = low.double(), (high - low).double()
    noise_var = max(result.noise_var, min_noise_std**2)
    jac = torch.as_tensor(result.jacobian, dtype=torch.float64)
    information = jac.T @ jac / noise_var
    prior_precision = torch.diag(span**2 / prior_std.double() ** 2)  # V0^-1 in unit coordinates
    precision = information + prior_precision
    precision = 0.5 * (precision + precision.T)
    u_star = torch.as_tensor(result.estimate, dtype=torch.float64)
    m0 = (prior_mean.double() - low) / span
    cov_u = torch.cholesky_inverse(torch.linalg.cholesky(precision))
    mean_u = cov_u @ (information @ u_star + prior_precision @ m0)
    cov = cov_u * span[:, None] * span[None, :]
    return LaplaceGaussian(low + span * mean_u, 0.5 * (cov + cov.T), float(np.sqrt(noise_var)))

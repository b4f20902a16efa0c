"""A Gaussian restricted to a box in many dimensions: its box probability and draws (GHK).

The Geweke-Hajivassiliou-Keane simulator writes theta = mean + L z (L the lower Cholesky
factor) and draws z_1, z_2, ... in turn, each from a standard normal truncated to the interval
that keeps theta_i inside the box given z_<i. The product of those intervals' probabilities is an
importance weight w with E[w] = P(box) exactly, so it estimates box probabilities far too small
for plain Monte Carlo (a 100-D posterior truncated to its prior box), and the weighted draws,
resampled, follow the truncated Gaussian.
"""

from __future__ import annotations

import math

import torch
from torch.special import log_ndtr, ndtri


def _log1mexp(x: torch.Tensor) -> torch.Tensor:
    """log(1 - exp(x)) for x <= 0, accurate near 0 and far below it."""
    return torch.where(x > -math.log(2), torch.log(-torch.expm1(x)), torch.log1p(-torch.exp(x)))


def truncated_standard_normal(lower: torch.Tensor, upper: torch.Tensor,
                              uniform: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Draws z ~ N(0, 1) restricted to [lower, upper] by inversion, and log P(lower <= z <= upper).

    Intervals in the upper tail are reflected into the lower tail, where the normal CDF keeps
    its relative precision, so intervals many standard deviations out stay exact.
    """
    flip = lower > 0
    lo, hi = torch.where(flip, -upper, lower), torch.where(flip, -lower, upper)
    log_hi, log_lo = log_ndtr(hi), log_ndtr(lo)
    log_mass = log_hi + _log1mexp(torch.clamp(log_lo - log_hi, max=0.0))
    log_p = torch.logaddexp(log_lo, torch.log(uniform) + log_mass)
    z = ndtri(torch.exp(log_p)).clamp(lo, hi)
    return torch.where(flip, -z, z), log_mass


def ghk(mean: torch.Tensor, scale_tril: torch.Tensor, low: torch.Tensor, high: torch.Tensor, num: int,
        generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """num weighted draws (theta [num, D], log_w [num]) of N(mean, L L^T) restricted to [low, high].

    logsumexp(log_w) - log(num) estimates log P(low <= theta <= high) without bias in P.
    """
    d = mean.shape[0]
    z = torch.zeros(num, d, dtype=torch.float64)
    log_w = torch.zeros(num, dtype=torch.float64)
    L = scale_tril.double()
    for i in range(d):
        shift = mean[i] + z[:, :i] @ L[i, :i]
        u = torch.rand(num, dtype=torch.float64, generator=generator).clamp_min(1e-300)
        z[:, i], log_mass = truncated_standard_normal((low[i] - shift) / L[i, i], (high[i] - shift) / L[i, i], u)
        log_w += log_mass
    theta = torch.minimum(torch.maximum(mean + z @ L.T, low), high)  # rounding at the faces
    return theta, log_w

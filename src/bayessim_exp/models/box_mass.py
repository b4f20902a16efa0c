"""The mass a Gaussian mixture's components put inside a box, differentiably: the normaliser of a mixture truncated to
the prior's box, the family a box-space posterior is used as (inference/bayessim/correction.py truncates it there).

Fitting the untruncated mixture by maximum likelihood to parameters that never leave the box pulls its components
inward and narrows them near the box's faces (mass outside the box costs likelihood), so that the truncated density
the posterior is read as falls off before a face where the true one stays flat: truths near a face, which the
simulations there do not pin down, fall outside its HPD regions (docs/statistics.md, "Truths near the box's
faces"). Fitting the truncated mixture (its log-density minus the log of its mass inside the box) removes that pull.

Exact per dimension for diagonal factors (products of normal CDF differences, any D), and for full factors in
D = 2 by Gauss-Legendre quadrature over the first coordinate of the second's conditional CDF difference; full factors
in more dimensions are not supported (`supported`).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..distributions.mixture import MixtureBatch

_NODES, _WEIGHTS = (torch.from_numpy(v) for v in np.polynomial.legendre.leggauss(24))
_QUADRATURE: dict = {}  # (device, dtype) -> the nodes and weights there: copied once, not inside a CUDA graph
_Z_BOUND = 7.0  # the first coordinate's standard scores are integrated over [-7, 7] at most: the rest is < 1e-11
_FLOOR = 1e-300


def supported(dim: int, diagonal: bool) -> bool:
    return diagonal or dim <= 2


def _log_ndtr_difference(lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """log(Phi(hi) - Phi(lo)) for lo <= hi, taken in the lower tail (mirrored where both lie above 0)."""
    upper = lo > 0
    lo, hi = torch.where(upper, -hi, lo), torch.where(upper, -lo, hi)
    return torch.log((torch.special.ndtr(hi) - torch.special.ndtr(lo)).clamp_min(_FLOOR))


def log_box_mass(means: torch.Tensor, U: torch.Tensor, low: torch.Tensor, high: torch.Tensor, *,
                 diagonal: bool) -> torch.Tensor:
    """log P_k(low <= theta <= high) [N, K] for components N(means [N, K, D], (U^T U)^-1), U [N, K, D, D] upper
    triangular precision factors; computed in float64."""
    dtype = means.dtype
    means, U = means.double(), U.double()
    low, high = low.double().to(means.device), high.double().to(means.device)
    d = means.shape[-1]
    if diagonal:
        sd = 1 / torch.diagonal(U, dim1=-2, dim2=-1)
        return _log_ndtr_difference((low - means) / sd, (high - means) / sd).sum(-1).to(dtype)
    if d == 1:
        sd = 1 / U[..., 0, 0]
        return _log_ndtr_difference((low[0] - means[..., 0]) / sd, (high[0] - means[..., 0]) / sd).to(dtype)
    if d != 2:
        raise ValueError(f"the box mass of full-covariance components is computed for D <= 2, not D = {d}")
    # U = [[a, b], [0, c]] (a, c > 0): the covariance (U^T U)^-1 is [[b^2 + c^2, -a b], [-a b, a^2]] / (a c)^2
    a, b, c = U[..., 0, 0], U[..., 0, 1], U[..., 1, 1]
    r = torch.sqrt(b**2 + c**2)
    s1, s2 = r / (a * c), 1 / c
    rho = (-b / r).clamp(-1 + 1e-9, 1 - 1e-9)
    za = ((low[0] - means[..., 0]) / s1).clamp(-_Z_BOUND, _Z_BOUND)
    zb = ((high[0] - means[..., 0]) / s1).clamp(-_Z_BOUND, _Z_BOUND)
    half, mid = (zb - za) / 2, (zb + za) / 2
    nodes, weights = _quadrature(means)
    z = mid[..., None] + half[..., None] * nodes  # [N, K, Q]
    m = means[..., 1, None] + (rho * s2)[..., None] * z  # the second coordinate's conditional mean and sd
    s = (s2 * torch.sqrt(1 - rho**2))[..., None]
    inner = torch.special.ndtr((high[1] - m) / s) - torch.special.ndtr((low[1] - m) / s)
    mass = half * (weights * torch.exp(-0.5 * z**2) * inner).sum(-1) / math.sqrt(2 * math.pi)
    return torch.log(mass.clamp_min(_FLOOR)).to(dtype)


def _quadrature(like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    key = (like.device, like.dtype)
    if key not in _QUADRATURE:
        _QUADRATURE[key] = (_NODES.to(like), _WEIGHTS.to(like))
    return _QUADRATURE[key]


def inside(theta: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """[...] bool: theta [..., D] inside the box."""
    return ((theta >= low) & (theta <= high)).all(-1)


_REDRAWS = 200  # rounds of redrawing the draws that left the box (a row with little mass inside: the rest clamped)


class TruncatedMixtureBatch(MixtureBatch):
    """A MixtureBatch truncated to the box [low, high] (the same units): the held-out checks of a model trained as
    that truncated mixture read it as it is used."""

    def __init__(self, log_weights: torch.Tensor, means: torch.Tensor, precision_factors: torch.Tensor,
                 low: torch.Tensor, high: torch.Tensor, *, diagonal: bool):
        super().__init__(log_weights, means, precision_factors)
        self.low, self.high = low.double(), high.double()
        self.log_mass = torch.logsumexp(
            self.log_weights + log_box_mass(self.means, self.factors, self.low, self.high, diagonal=diagonal), -1)

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        lp = super().log_prob(theta) - self.log_mass
        return torch.where(inside(theta.double(), self.low, self.high), lp, -math.inf)

    def sample(self, count: int, generator: torch.Generator | None = None) -> torch.Tensor:
        out = super().sample(count, generator)
        for _ in range(_REDRAWS):
            outside = ~inside(out, self.low, self.high)
            if not outside.any():
                break
            out = torch.where(outside[..., None], super().sample(count, generator), out)
        return torch.maximum(torch.minimum(out, self.high), self.low)

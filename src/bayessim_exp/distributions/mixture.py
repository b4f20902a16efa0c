"""Gaussian mixtures: density, sampling, affine maps, products, and truncation to a box.

The posterior of every mixture-density model is a `GaussianMixture`; conditioning returns it
truncated to the prior's support (`TruncatedMixture`), renormalised rather than clipped.
"""

from __future__ import annotations

import functools
import logging
import math

import torch

from ..data_files import data_class
from .base import NOT_GAUSSIAN, ParameterDistribution
from .box import inside, restrict_log_prob
from .ghk import ghk
from .rejection import sample_by_rejection

log = logging.getLogger(__name__)

_LOG_2PI = math.log(2 * math.pi)
# relative diagonal jitter tried, in turn, on covariances that rounding left not positive definite
_JITTER = (1e-12, 1e-10, 1e-8, 1e-6, 1e-4)


def is_diagonal(matrices: torch.Tensor) -> bool:
    """Every [..., D, D] matrix zero off its diagonal."""
    return not bool(torch.any(matrices - torch.diag_embed(torch.diagonal(matrices, dim1=-2, dim2=-1))))


class NotPositiveDefinite(ValueError):
    """A covariance double precision cannot factorise, jitter included (variances 1e14 beside 1e-10)."""


def _cholesky(covs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(covs, lower Cholesky factors), adding the smallest relative jitter that makes them factorise."""
    if not torch.isfinite(covs).all():
        raise ValueError("a mixture component's covariance is not finite")
    factor, info = torch.linalg.cholesky_ex(covs)
    if not info.any():
        return covs, factor
    failed = int((info != 0).sum())
    scale = torch.diag_embed(torch.diagonal(covs, dim1=-2, dim2=-1).abs().clamp_min(torch.finfo(covs.dtype).tiny))
    for eps in _JITTER:
        fixed = covs + eps * scale
        factor, info = torch.linalg.cholesky_ex(fixed)
        if not info.any():
            log.warning("%d mixture covariance(s) not positive definite by rounding; added %.0e of their diagonal",
                        failed, eps)
            return fixed, factor
    raise NotPositiveDefinite("a mixture component's covariance is not positive definite, even with jitter")


class MixtureBatch:
    """One Gaussian mixture per row n, for many rows at once (a model's q(theta | x_n) on held-out
    summaries): log weights [N, M], means [N, M, D], upper-triangular precision factors U [N, M, D, D]
    with cov = (U^T U)^-1, float64. Loops over components, never over rows."""

    def __init__(self, log_weights: torch.Tensor, means: torch.Tensor, precision_factors: torch.Tensor):
        self.log_weights = torch.log_softmax(log_weights.double(), -1)
        self.means, self.factors = means.double(), precision_factors.double()

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        """log q_n(theta[..., n, :]) for theta [..., N, D]: [..., N]."""
        theta = theta.double()
        half_logdet = torch.log(torch.diagonal(self.factors, dim1=-2, dim2=-1)).sum(-1)  # [N, M]
        per_component = []
        for m in range(self.means.shape[1]):
            z = torch.einsum("nij,...nj->...ni", self.factors[:, m], theta - self.means[:, m])
            per_component.append(half_logdet[:, m] - 0.5 * (z**2).sum(-1))
        d = self.means.shape[-1]
        return torch.logsumexp(self.log_weights + torch.stack(per_component, -1), -1) - 0.5 * d * _LOG_2PI

    def sample(self, count: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """`count` draws from every row's mixture: [count, N, D]."""
        n, k, d = self.means.shape
        comp = torch.multinomial(self.log_weights.exp(), count, replacement=True, generator=generator).T  # [count, N]
        eps = torch.randn(count, n, d, dtype=torch.float64, generator=generator)
        out = torch.zeros(count, n, d, dtype=torch.float64)
        eye = torch.eye(d, dtype=torch.float64)
        for m in range(k):
            factor_inv = torch.linalg.solve_triangular(self.factors[:, m], eye.expand(n, d, d), upper=True)
            draws = self.means[:, m] + torch.einsum("nij,cnj->cni", factor_inv, eps)
            out = torch.where((comp == m)[..., None], draws, out)
        return out


@data_class
class GaussianMixture(ParameterDistribution):
    """sum_k w_k N(mean_k, cov_k) over R^D, float64."""

    def __init__(self, logits: torch.Tensor, means: torch.Tensor, covs: torch.Tensor):
        self.log_weights = torch.log_softmax(logits.double(), -1)
        self.means = means.double()
        self.covs, self.scale_tril = _cholesky(0.5 * (covs.double() + covs.double().transpose(-1, -2)))

    @property
    def num_components(self) -> int:
        return self.means.shape[0]

    @functools.cached_property
    def diagonal_std(self) -> torch.Tensor | None:
        """The components' standard deviations [K, D] where every covariance is diagonal (a diagonal model's
        posteriors: densities and draws elementwise, D per point instead of D^2), else None."""
        return torch.diagonal(self.scale_tril, dim1=-2, dim2=-1) if is_diagonal(self.scale_tril) else None

    def gaussian_factor(self) -> tuple[torch.Tensor, torch.Tensor] | str:
        return (self.means[0], self.covs[0]) if self.num_components == 1 else NOT_GAUSSIAN

    def as_gaussian_mixture(self) -> GaussianMixture:
        return self

    @property
    def dim(self) -> int:
        return self.means.shape[1]

    def component_log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        """log N(theta; mean_k, cov_k) for every component: [..., K]."""
        flat = theta.double().reshape(-1, self.dim)
        std = torch.diagonal(self.scale_tril, dim1=-2, dim2=-1)  # [K, D]
        half_logdet = torch.log(std).sum(-1)
        if self.diagonal_std is not None:
            # a diagonal model's posteriors: K D per point, not K D^2, expanded into three matrix products; centred on
            # the components' mean first, so the expansion cancels only where the points are far from every component
            centre = self.means.mean(0)
            x, m, precision = flat - centre, self.means - centre, std.pow(-2)
            quadratic = ((x * x) @ precision.T - 2 * x @ (precision * m).T + (precision * m * m).sum(-1)).clamp_min(0)
        else:  # one triangular solve per component over all points: [K, D, N], never [N, K, D, D]
            diff = flat.T.unsqueeze(0) - self.means.unsqueeze(-1)
            quadratic = torch.linalg.solve_triangular(self.scale_tril, diff, upper=False).pow(2).sum(1).T
        out = -0.5 * quadratic - half_logdet - 0.5 * self.dim * _LOG_2PI
        return out.reshape(*theta.shape[:-1], self.num_components)

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        return torch.logsumexp(self.log_weights + self.component_log_prob(theta), -1)

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        comp = torch.multinomial(self.log_weights.exp(), n, replacement=True, generator=generator)
        eps = torch.randn(n, self.dim, dtype=torch.float64, generator=generator)
        out = torch.empty(n, self.dim, dtype=torch.float64)
        # one matrix product per component, never a [n, D, D] stack of factors
        for k in torch.unique(comp).tolist():
            rows = comp == k
            out[rows] = self.means[k] + eps[rows] @ self.scale_tril[k].T
        return out.reshape(*shape, self.dim)

    @property
    def mean(self) -> torch.Tensor:
        return (self.log_weights.exp()[:, None] * self.means).sum(0)

    @property
    def covariance(self) -> torch.Tensor:
        w = self.log_weights.exp()
        mu = self.mean
        d = self.means - mu
        return (w[:, None, None] * (self.covs + d[:, :, None] * d[:, None, :])).sum(0)

    @property
    def stddev(self) -> torch.Tensor:
        return torch.diagonal(self.covariance).sqrt()

    def affine(self, shift: torch.Tensor, scale: torch.Tensor) -> GaussianMixture:
        """The mixture of shift + scale * theta (scale a vector: a diagonal map)."""
        s = scale.double()
        return GaussianMixture(self.log_weights, self.means * s + shift.double(), self.covs * s[:, None] * s[None, :])

    def product(self, other: GaussianMixture, max_components: int | None = None) -> GaussianMixture:
        """The normalised product density p(theta) * q(theta) / Z, a mixture of K1*K2 Gaussians, or of its
        `max_components` heaviest (renormalised, as `prune`): only those get their means and covariances, the
        costly part in many dimensions.

        N(a, A) N(b, B) = N(a; b, A + B) * N(c, C) with C = (A^-1 + B^-1)^-1, c = C (A^-1 a + B^-1 b).
        """
        a, b = self.means[:, None], other.means[None, :]  # [K1, 1, D], [1, K2, D]
        L = torch.linalg.cholesky(self.covs[:, None] + other.covs[None, :])
        z = torch.linalg.solve_triangular(L, (a - b).unsqueeze(-1), upper=False).squeeze(-1)
        log_norm = -0.5 * (z**2).sum(-1) - torch.log(torch.diagonal(L, dim1=-2, dim2=-1)).sum(-1) - 0.5 * self.dim * _LOG_2PI
        logits = (self.log_weights[:, None] + other.log_weights[None, :] + log_norm).reshape(-1)
        keep = torch.arange(len(logits))
        if max_components is not None and len(logits) > max_components:
            keep = torch.topk(logits, max_components).indices
        i, j = keep // other.num_components, keep % other.num_components
        A, B, L = self.covs[i], other.covs[j], L.reshape(-1, self.dim, self.dim)[keep]
        # C = A S^-1 B and c = B S^-1 a + A S^-1 b, symmetric and stable without inverting A or B
        C = A @ torch.cholesky_solve(B, L)
        c = (B @ torch.cholesky_solve(self.means[i].unsqueeze(-1), L)
             + A @ torch.cholesky_solve(other.means[j].unsqueeze(-1), L)).squeeze(-1)
        return GaussianMixture(logits[keep], c, C)

    def superlevel_box(self, level: float) -> tuple[torch.Tensor, torch.Tensor] | None:
        """A box (lo, hi) holding every theta where log q(theta) >= level; None where that set is empty.

        Where the K weighted components sum to e^level, one of them reaches e^level / K, so the set lies in the
        union of one ellipsoid per component, (theta - m)^T P (theta - m) <= r^2 with P the component's precision.
        The box spans each ellipsoid's extent along the axes, m +- r sqrt(diag P^-1).
        """
        half_logdet_cov = torch.log(torch.diagonal(self.scale_tril, dim1=-2, dim2=-1)).sum(-1)
        # log w_k + log N(theta; m_k, C_k) = const_k - (theta - m_k)^T P_k (theta - m_k) / 2
        const = self.log_weights - half_logdet_cov - 0.5 * self.dim * _LOG_2PI
        radius_sq = 2 * (const - level + math.log(self.num_components))
        reached = radius_sq >= 0
        if not reached.any():
            return None
        extent = (radius_sq[:, None].clamp_min(0) * torch.diagonal(self.covs, dim1=-2, dim2=-1)).sqrt()
        return (self.means - extent)[reached].min(0).values, (self.means + extent)[reached].max(0).values

    def prune(self, max_components: int) -> GaussianMixture:
        """Keep the heaviest components (renormalised)."""
        if self.num_components <= max_components:
            return self
        keep = torch.topk(self.log_weights, max_components).indices
        return GaussianMixture(self.log_weights[keep], self.means[keep], self.covs[keep])


@data_class
class TruncatedMixture(ParameterDistribution):
    """A mixture restricted to the box [low, high] and renormalised.

    The normaliser P(box) is estimated once by Monte Carlo with `num_mc` draws, and sampling is
    exact, by rejection. When fewer than `min_hits` of those draws land inside (a posterior in
    many dimensions, or one far from the box), each component's box probability is estimated by
    the GHK simulator instead (distributions/ghk.py, `num_mc` // 50 weighted draws per
    component) and draws come from GHK importance resampling: exact as the draws grow, and
    repeatable.
    """

    def __init__(self, mixture: GaussianMixture, low: torch.Tensor, high: torch.Tensor,
                 num_mc: int = 200_000, seed: int = 0, min_hits: int = 200):
        self.mixture = mixture
        self.low, self.high = low.double(), high.double()
        g = torch.Generator().manual_seed(seed)
        hits = int(inside(mixture.sample((num_mc,), generator=g), self.low, self.high).sum())
        self.by_rejection = hits >= min_hits
        if self.by_rejection:
            self.component_log_mass = None
            self._log_mass = math.log(hits / num_mc)
        else:
            self._ghk_draws = max(1000, num_mc // 50)
            self.component_log_mass = torch.stack([
                torch.logsumexp(ghk(m, L, self.low, self.high, self._ghk_draws, g)[1], 0) - math.log(self._ghk_draws)
                for m, L in zip(mixture.means, mixture.scale_tril)
            ])
            self._log_mass = float(torch.logsumexp(mixture.log_weights + self.component_log_mass, 0))
        if not math.isfinite(self._log_mass):
            raise ValueError(
                "the posterior puts no measurable mass inside the prior's support; "
                "the real data may not match the simulator or the model is badly fitted"
            )
        self._generator = torch.Generator().manual_seed(seed + 1)

    def superlevel_box(self, level: float) -> tuple[torch.Tensor, torch.Tensor] | None:
        return self.mixture.superlevel_box(level + self._log_mass)

    def gaussian_factor(self) -> tuple[torch.Tensor, torch.Tensor] | str:
        return self.mixture.gaussian_factor()  # truncation only restricts the support

    @property
    def log_mass_inside(self) -> float:
        return self._log_mass

    @property
    def dim(self) -> int:
        return self.mixture.dim

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        return restrict_log_prob(self.mixture.log_prob(theta) - self._log_mass, theta, self.low, self.high)

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        g = generator or self._generator
        n = math.prod(shape)
        if self.by_rejection:
            draws = sample_by_rejection(lambda b: self.mixture.sample((b,), generator=g),
                                        lambda t: inside(t, self.low, self.high), n, math.exp(self._log_mass))
        else:
            draws = self._resampled(n, g)
        return draws.reshape(*shape, self.dim)

    def _resampled(self, n: int, g: torch.Generator) -> torch.Tensor:
        """Components by their truncated weight, then GHK draws resampled by their weights."""
        weights = torch.softmax(self.mixture.log_weights + self.component_log_mass, 0)
        counts = torch.bincount(torch.multinomial(weights, n, replacement=True, generator=g),
                                minlength=self.mixture.num_components)
        out = []
        for k in torch.nonzero(counts).flatten().tolist():
            pool = max(self._ghk_draws, 4 * int(counts[k]))
            theta, log_w = ghk(self.mixture.means[k], self.mixture.scale_tril[k], self.low, self.high, pool, g)
            pick = torch.multinomial(torch.softmax(log_w, 0), int(counts[k]), replacement=True, generator=g)
            out.append(theta[pick])
        return torch.cat(out)[torch.randperm(n, generator=g)]

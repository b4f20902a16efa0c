"""Exact draws from N(0, I) restricted to a Gaussian mixture's superlevel set over N(0, I), in many dimensions.

The truncated proposal (truncated_prior.py) is the prior restricted to a posterior's highest-density region; in
probit space the prior is N(0, I) and, for a mixture posterior q, the region lies in

    S = {u : log q(u) - log N(u; 0, I) >= level}.

A box around S holds a vanishing share of it in many dimensions (an ellipsoid fills 1e-13 of its bounding box in
30), and the whole prior a vanishing share too when the posterior is narrow. Rejection from q itself fails the
other way: the prior restricted to S is nearly flat on it, so its mass sits at the rim, where q has little.

The candidates here come from one Gaussian per component, N(0, I) tilted towards the component:
g_k(u) proportional to N(u; 0, I) exp(beta_k f_k(u)), with log w_k N(u; m_k, C_k) - log N(u; 0, I) =
c_k + f_k(u), f_k(u) = -u^T A_k u / 2 + b_k^T u, A_k = P_k - I, b_k = P_k m_k (P_k = C_k^-1). beta = 0 is the prior,
beta = 1 the component itself; in between, narrow directions reach the rim and wide ones keep the prior's width.
Where the K components sum to e^level one of them reaches e^level / K, f_k(u) >= h_k = level - log K - c_k, and
there N(u; 0, I) / g_k(u) <= Z_k exp(-beta_k h_k) =: B_k (Z_k: g_k's normaliser). Drawing component k with
probability B_k / B (B = sum B_k) and accepting u with probability

    a(u) = 1 / sum_k exp(beta_k (f_k(u) - h_k))         (at most 1 on S)

gives N(0, I) restricted to S exactly once the draws outside S are dropped, and S's prior mass is B times the
share of candidates accepted and inside. That share is the mass over B, so each beta_k is the one that makes B_k
smallest (closed form in A_k's eigenbasis): for a narrow Gaussian the tilted draws then sit at the rim of the
region, about a tenth of the candidates kept in 30 dimensions (tests/unit/test_truncated_prior.py).
"""

from __future__ import annotations

import math

import torch

from .mixture import GaussianMixture

# the tilts tried: log B_k(beta) is convex in beta (a log-partition function minus a linear term), so the best of a
# fine grid is within a few per cent of the best acceptance
_BETAS = torch.logspace(-4, 0, 161, dtype=torch.float64)


class RelaxedCover:
    """Candidates for N(0, I) restricted to {log q(u) - log N(u; 0, I) >= level}, q a Gaussian mixture: `draw`
    returns those that pass the acceptance step; `log_bound` is log B (the region's prior mass is B times the
    share of candidates that pass and lie in the region)."""

    def __init__(self, mixture: GaussianMixture, level: float):
        d, k = mixture.dim, mixture.num_components
        eye = torch.eye(d, dtype=torch.float64)
        precision = torch.cholesky_inverse(mixture.scale_tril)
        self.A = precision - eye
        self.b = (precision @ mixture.means.unsqueeze(-1)).squeeze(-1)
        half_logdet_cov = torch.log(torch.diagonal(mixture.scale_tril, dim1=-2, dim2=-1)).sum(-1)
        const = mixture.log_weights - half_logdet_cov - 0.5 * (self.b * mixture.means).sum(-1)
        self.h = level - math.log(k) - const
        # log B_k(beta) = -log|I + beta A| / 2 + beta^2 b^T (I + beta A)^-1 b / 2 - beta h, in A's eigenbasis
        values, vectors = torch.linalg.eigh(0.5 * (self.A + self.A.transpose(-1, -2)))
        b_sq = (vectors.transpose(-1, -2) @ self.b.unsqueeze(-1)).squeeze(-1) ** 2
        scale = 1 + _BETAS[:, None, None] * values  # [grid, K, D], positive: A > -I and beta <= 1
        log_bounds = (-0.5 * torch.log(scale).sum(-1) + 0.5 * _BETAS[:, None] ** 2 * (b_sq / scale).sum(-1)
                      - _BETAS[:, None] * self.h)
        best = log_bounds.argmin(0)  # the acceptance is the region's prior mass over B: the smallest B is best
        self.beta = _BETAS[best]
        log_bounds = log_bounds.gather(0, best[None])[0]
        # g_k = N(mean_k, (I + beta_k A_k)^-1): positive definite as A_k > -I and beta_k <= 1
        tilted_precision = eye + self.beta[:, None, None] * self.A
        tilted_chol = torch.linalg.cholesky(tilted_precision)
        self.means = torch.cholesky_solve((self.beta[:, None] * self.b).unsqueeze(-1), tilted_chol).squeeze(-1)
        self.log_bound = float(torch.logsumexp(log_bounds, 0))
        self.log_weights = log_bounds - self.log_bound
        # draws: mean + L^-T eps with tilted_precision = L L^T
        self.tilted_chol = tilted_chol
        # a diagonal model's posterior (its products and tempering stay diagonal): every step elementwise, K D per
        # candidate instead of K D^2 (ShadowHand_more's 102 parameters and 50 components: docs/benchmarks.md)
        self.diagonal = mixture.diagonal_std is not None

    def _log_accept(self, u: torch.Tensor) -> torch.Tensor:
        if self.diagonal:
            f = -0.5 * (u * u) @ torch.diagonal(self.A, dim1=-2, dim2=-1).T + u @ self.b.T
        else:
            f = torch.stack([-0.5 * ((u @ a) * u).sum(-1) for a in self.A], -1) + u @ self.b.T  # a product a component
        return -torch.logsumexp(self.beta * (f - self.h), -1)

    def draw(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """The candidates among n draws of the tilted mixture that pass the acceptance step: [<= n, D]."""
        comp = torch.multinomial(self.log_weights.exp(), n, replacement=True, generator=generator)
        eps = torch.randn(n, self.means.shape[1], dtype=torch.float64, generator=generator)
        if self.diagonal:
            u = self.means[comp] + eps / torch.diagonal(self.tilted_chol, dim1=-2, dim2=-1)[comp]
        else:
            u = self._correlated_draws(comp, eps)
        keep = torch.rand(n, dtype=torch.float64, generator=generator).log() < self._log_accept(u)
        return u[keep]

    def _correlated_draws(self, comp: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        u = torch.empty_like(eps)
        for k in torch.unique(comp).tolist():
            rows = comp == k
            u[rows] = self.means[k] + torch.linalg.solve_triangular(
                self.tilted_chol[k].T, eps[rows].T, upper=True).T
        return u

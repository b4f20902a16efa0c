"""A linear-Gaussian simulator x = A theta + b + noise, whose posteriors are known in closed form."""

from __future__ import annotations

import torch


class LinearGaussian:
    def __init__(self, A: torch.Tensor, b: torch.Tensor, noise_cov: torch.Tensor):
        self.A, self.b, self.noise_cov = A.double(), b.double(), noise_cov.double()
        self._noise_tril = torch.linalg.cholesky(self.noise_cov)

    def simulate(self, theta: torch.Tensor, seed: int) -> torch.Tensor:
        g = torch.Generator().manual_seed(seed)
        eps = torch.randn(theta.shape[0], self.A.shape[0], dtype=torch.float64, generator=g)
        return theta.double() @ self.A.T + self.b + eps @ self._noise_tril.T

    def posterior(self, mean0: torch.Tensor, cov0: torch.Tensor, xs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and covariance of theta | x_1..n under the Gaussian prior N(mean0, cov0); xs [n, F]."""
        noise_prec = torch.linalg.inv(self.noise_cov)
        prec = torch.linalg.inv(cov0.double()) + xs.shape[0] * self.A.T @ noise_prec @ self.A
        shift = torch.linalg.solve(cov0.double(), mean0.double()) + self.A.T @ noise_prec @ (xs.double() - self.b).sum(0)
        cov = torch.linalg.inv(prec)
        return cov @ shift, cov


def gaussian_draws(mean: torch.Tensor, cov: torch.Tensor, n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return mean.double() + torch.randn(n, mean.shape[0], dtype=torch.float64, generator=g) @ torch.linalg.cholesky(cov.double()).T

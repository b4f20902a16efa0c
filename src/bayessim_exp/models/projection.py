"""Regression summaries: the summaries replaced by a ridge regression's prediction of the parameters.

With hundreds of summary features (`start`, `corrdiff` on a humanoid) and a few thousand
simulations, a network on the raw features overfits after a few epochs and its posteriors are
overconfident. Predicting the parameters linearly first and feeding the D predictions to the
network (semi-automatic ABC's summaries, Fearnhead & Prangle 2012) keeps what is linearly
decodable in D inputs. The training inputs are out-of-fold predictions, so the network sees
predictions as noisy as the ones it will get for new data; new data use the fit on all of it.
"""

from __future__ import annotations

import torch
from torch import nn

_PENALTIES = (1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)  # tried on standardised summaries, best by held-out error
_FOLDS = 5


class RidgeSystem:
    """[z, 1] W = y with the intercept unpenalised, solved for any penalty and any rows left out.

    With more rows than features, the normal equations are formed once and a fold's Gram matrix is
    subtracted rather than recomputed. With more features than rows (signature summaries give thousands),
    the same weights come from the dual: on data centred by the fitted rows' means (which makes the
    intercept unpenalised), w = Zc^T (Zc Zc^T + penalty I)^-1 Yc, a rows-by-rows system.
    """

    def __init__(self, z: torch.Tensor, y: torch.Tensor):
        self.design = torch.cat([z.double(), torch.ones(len(z), 1, dtype=torch.float64, device=z.device)], 1)
        self.y = y.double()
        self.dual = z.shape[1] > len(z)
        self._kernel = None  # the dual's centred kernel of all rows, shared by every penalty
        if not self.dual:
            self.gram, self.moment = self.design.T @ self.design, self.design.T @ self.y

    def solve(self, penalty: float, leave_out: torch.Tensor | None = None) -> torch.Tensor:
        """[F + 1, D] weights (last row: intercept, not penalised), fitted without the rows `leave_out` (bool)."""
        if self.dual:
            return self._solve_dual(penalty, leave_out)
        gram, moment = self.gram, self.moment
        if leave_out is not None:
            d = self.design[leave_out]
            gram, moment = gram - d.T @ d, moment - d.T @ self.y[leave_out]
        reg = penalty * torch.ones(gram.shape[0], dtype=gram.dtype, device=gram.device)
        reg[-1] = 0.0
        return torch.linalg.solve(gram + torch.diag(reg), moment)

    def _solve_dual(self, penalty: float, leave_out: torch.Tensor | None) -> torch.Tensor:
        z, y = self.design[:, :-1], self.y
        if leave_out is not None:
            z, y = z[~leave_out], y[~leave_out]
            centred = _centred_kernel(z, y)
        else:  # formed once (rows^2 x features: the dual's cost), not once per penalty
            if self._kernel is None:
                self._kernel = _centred_kernel(z, y)
            centred = self._kernel
        zc, kernel, z_mean, y_mean = centred
        # positive definite for any penalty > 0: Cholesky, half the work of a general solve
        factor = torch.linalg.cholesky(kernel + penalty * torch.eye(len(kernel), dtype=kernel.dtype, device=kernel.device))
        w = zc.T @ torch.cholesky_solve(y - y_mean, factor)
        return torch.cat([w, (y_mean - z_mean @ w)[None]])

    def predict(self, rows: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        return self.design[rows] @ weights


def _centred_kernel(z: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """(zc, zc zc^T, z's column means, y's column means) of rows z, y centred by their means."""
    z_mean = z.mean(0)
    zc = z - z_mean
    return zc, zc @ zc.T, z_mean, y.mean(0)


class RidgeProjection(nn.Module):
    """Standardised summaries [N, F] -> predicted standardised parameters [N, D]."""

    def __init__(self, x_dim: int, theta_dim: int):
        super().__init__()
        self.register_buffer("weight", torch.zeros(x_dim, theta_dim))
        self.register_buffer("bias", torch.zeros(theta_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x @ self.weight + self.bias

    @torch.no_grad()
    def fit(self, x: torch.Tensor, theta: torch.Tensor, seed: int) -> torch.Tensor:
        """Fit on all pairs; return the out-of-fold predictions for the same pairs [N, D]."""
        system = RidgeSystem(x, theta)
        folds = (torch.randperm(len(x), generator=torch.Generator().manual_seed(seed)) % _FOLDS).to(x.device)
        held = folds == 0
        errors = [float((system.y[held] - system.predict(held, system.solve(p, held))).pow(2).mean()) for p in _PENALTIES]
        penalty = _PENALTIES[min(range(len(errors)), key=errors.__getitem__)]
        out_of_fold = torch.empty_like(system.y)
        for k in range(_FOLDS):
            inside = folds == k
            out_of_fold[inside] = system.predict(inside, system.solve(penalty, inside))
        w = system.solve(penalty)
        self.weight.copy_(w[:-1].float())
        self.bias.copy_(w[-1].float())
        return out_of_fold.float()

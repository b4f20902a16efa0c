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
    intercept unpenalised), w = Zc^T (Zc Zc^T + penalty I)^-1 Yc, a rows-by-rows system whose kernel every
    penalty and fold takes from one Gram matrix of all rows.
    """

    def __init__(self, z: torch.Tensor, y: torch.Tensor):
        self.design = torch.cat([z.double(), torch.ones(len(z), 1, dtype=torch.float64, device=z.device)], 1)
        self.y = y.double()
        self.dual = z.shape[1] > len(z)
        self._gram = None  # the dual's z z^T over all rows (formed at its first solve)
        self._kernel_of = None  # (rows left out, z, y, centred kernel) of the last dual solve
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
        z, y, kernel = self._centred_kernel(leave_out)
        shifted = kernel.clone()
        shifted.diagonal().add_(penalty)
        # positive definite for any penalty > 0: Cholesky, half the work of a general solve
        factor = torch.linalg.cholesky(shifted)
        del shifted  # rows^2 doubles, not kept through the solve
        z_mean, y_mean = z.mean(0), y.mean(0)
        alpha = torch.cholesky_solve(y - y_mean, factor)
        w = z.T @ alpha - z_mean[:, None] * alpha.sum(0)  # (z - mean)^T alpha without the centred copy of z
        return torch.cat([w, (y_mean - z_mean @ w)[None]])

    def _centred_kernel(self, leave_out: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(z, y, (z - mean)(z - mean)^T) of the rows kept, the kernel kept for the next solve on the same rows
        (every penalty is tried on one split: its centring passes over rows^2 doubles several times)."""
        cached = self._kernel_of
        if cached is not None and (cached[0] is None if leave_out is None
                                   else cached[0] is not None and torch.equal(cached[0], leave_out)):
            return cached[1:]
        if self._gram is None:  # rows^2 x features: the dual's cost, paid once
            z_all = self.design[:, :-1]
            self._gram = z_all @ z_all.T
        z, y, gram = self.design[:, :-1], self.y, self._gram
        if leave_out is not None:
            keep = ~leave_out
            z, y, gram = z[keep], y[keep], gram[keep][:, keep]
        # the centred rows' kernel from the Gram by double centring
        row = gram.mean(1, keepdim=True)
        kernel = gram - row - row.T + gram.mean()
        self._kernel_of = (None if leave_out is None else leave_out.clone(), z, y, kernel)
        return z, y, kernel

    def predict(self, rows: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        return self.design[rows] @ weights


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

"""Linear-Gaussian q(theta | x) = N(A x + b, S): ridge regression of the parameters on the summaries,
with the residual covariance as the posterior's. The baseline any model worth shipping beats
(benchmarks/inference_tasks.py); exact when the parameters are linear in the summaries with
Gaussian noise. The ridge penalty is chosen from `penalties` by the held-out split's mean squared
residual (standardised parameters); the covariance is
that of the held-out residuals (in-sample residuals are too small when summaries have hundreds of
features), of the held-out pairs among `calibration_rows` when the caller names them (the latest
round's), and the weights are then refitted on all the data.
"""

from __future__ import annotations

import dataclasses

import torch

from ..data_files import data_class
from ..distributions.mixture import GaussianMixture, MixtureBatch
from ..errors import ConfigError, TrainingError
from .base import SavedAsData, column_scale
from .projection import RidgeSystem


@data_class
@dataclasses.dataclass
class LinearConfig:
    penalties: list[float]  # ridge penalties tried, on standardised summaries
    val_fraction: float

    def validate(self) -> None:
        if not self.penalties or any(p < 0 for p in self.penalties):
            raise ConfigError(f"penalties must be a non-empty list of values >= 0, got {self.penalties}")
        if not 0.0 < self.val_fraction < 0.5:
            raise ConfigError(f"val_fraction must be in (0, 0.5), got {self.val_fraction}")


def _predict(z: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    return z @ weights[:-1] + weights[-1]


@data_class
class LinearGaussian(SavedAsData):
    def __init__(self, cfg: LinearConfig, theta_dim: int, x_dim: int):
        self.cfg, self.theta_dim, self.x_dim = cfg, theta_dim, x_dim
        self.shift, self.scale = torch.zeros(x_dim, dtype=torch.float64), torch.ones(x_dim, dtype=torch.float64)
        self.weights = torch.zeros(x_dim + 1, theta_dim, dtype=torch.float64)
        self.cov = torch.eye(theta_dim, dtype=torch.float64)

    def _gaussian_nll(self, residual: torch.Tensor, cov: torch.Tensor) -> float:
        return -float(torch.distributions.MultivariateNormal(torch.zeros_like(residual[0]), cov).log_prob(residual).mean())

    def fit(self, theta: torch.Tensor, x: torch.Tensor, *, seed: int, label: str = "", on_epoch=None,
            calibration_rows: torch.Tensor | None = None, calibration_only: torch.Tensor | None = None) -> dict:
        theta, x = theta.double(), x.double()
        n = len(theta)
        n_val = max(1, int(round(self.cfg.val_fraction * n)))
        if n - n_val <= 2:
            raise TrainingError(f"{label}: {n} simulations are too few to train on")
        self.shift, self.scale = x.mean(0), column_scale(x)
        z = (x - self.shift) / self.scale
        val = torch.zeros(n, dtype=torch.bool)
        val[torch.randperm(n, generator=torch.Generator().manual_seed(seed))[:n_val]] = True
        only = torch.zeros(n, dtype=torch.bool) if calibration_only is None else calibration_only.cpu()
        val &= ~only
        # the covariance from the held-out pairs drawn like the ones conditioned on, where enough of them are
        held = val | only
        spread = (only if calibration_only is not None else val) & (True if calibration_rows is None
                                                                      else calibration_rows.cpu())
        spread = spread[held] if int(spread.sum()) > self.theta_dim else val[held]
        system = RidgeSystem(z, theta)
        theta_scale = theta.std(0).clamp_min(1e-12)
        scores, covs = [], []
        for penalty in self.cfg.penalties:
            resid_held = theta[held] - system.predict(held, system.solve(penalty, held))
            covs.append(torch.cov(resid_held[spread].T).reshape(self.theta_dim, self.theta_dim))
            scores.append(float((resid_held[val[held]] / theta_scale).pow(2).mean()))
        best = min(range(len(scores)), key=scores.__getitem__)
        self.weights = system.solve(self.cfg.penalties[best], only if calibration_only is not None else None)
        self.cov = covs[best]
        train_nll = self._gaussian_nll(theta - _predict(z, self.weights), self.cov)
        val_nll = self._gaussian_nll(theta[val] - system.predict(val, self.weights), self.cov)
        return {"train": [train_nll], "val": [val_nll], "best_val": val_nll, "epochs": 1,
                "penalty": self.cfg.penalties[best]}

    def inputs(self, x: torch.Tensor) -> torch.Tensor:
        """The standardised summaries the regression reads."""
        return (x.double() - self.shift) / self.scale

    @torch.no_grad()
    def conditional(self, x_obs: torch.Tensor) -> GaussianMixture:
        return GaussianMixture(torch.zeros(1), _predict(self.inputs(x_obs.reshape(1, -1)), self.weights), self.cov[None])

    @torch.no_grad()
    def conditionals(self, x: torch.Tensor) -> MixtureBatch:
        """q(theta | x_n) for every row of x [N, F] (held-out checks, batched)."""
        means = _predict(self.inputs(x), self.weights)
        factor = torch.linalg.cholesky(torch.linalg.inv(self.cov), upper=True)
        n, d = means.shape
        return MixtureBatch(torch.zeros(n, 1), means[:, None], factor.expand(n, 1, d, d))

    def state_dict(self) -> dict:
        return {"shift": self.shift, "scale": self.scale, "weights": self.weights, "cov": self.cov}

    def load_state_dict(self, state: dict) -> None:
        self.shift, self.scale, self.weights, self.cov = state["shift"], state["scale"], state["weights"], state["cov"]


def linear(cfg: LinearConfig, theta_dim: int, x_dim: int) -> LinearGaussian:
    return LinearGaussian(cfg, theta_dim, x_dim)

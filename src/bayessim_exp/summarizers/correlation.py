"""`corr` and `corrdiff`: state-action cross-correlations over time, plus channel means and stds.

The statistics of the original BayesSim paper (Ramos et al. 2019), generalised to lags: with
every channel standardised over the valid steps of its own trajectory (z = (x - mean) / std,
std with n-1), the feature for state channel i, action channel j and lag l is

    c_ij[l] = sum_{t=l}^{n-1} z_si[t] * z_aj[t-l] / (n - 1)

so c_ij[0] is the Pearson correlation and a state that follows an action by d steps peaks at
l = d. `corr` uses the states s[t] seen before a[t]; `corrdiff` the differences s[t+1] - s[t]
that a[t] produced. Only the n valid steps enter; a constant channel standardises to 0.
"""

from __future__ import annotations

import dataclasses

import torch

from ..errors import ConfigError
from ..sim.trajectories import Trajectories
from .masking import held_states


@dataclasses.dataclass
class CorrelationConfig:
    lags: int  # L: lags 0..L, in control steps

    def validate(self) -> None:
        if self.lags < 0:
            raise ConfigError(f"lags must be >= 0, got {self.lags}")


def masked_moments(x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and standard deviation (n-1) of x [N, T, C] over the steps where mask [N, T] holds.

    Computed on x - x[:, :1] so that a constant channel has exactly zero variance; fewer than
    two valid steps give std 0.
    """
    m = mask[..., None].to(x.dtype)
    n = m.sum(1)
    shifted = (x - x[:, :1]) * m
    mean_shifted = shifted.sum(1) / n.clamp_min(1)
    var = (((shifted - mean_shifted[:, None]) * m) ** 2).sum(1) / (n - 1).clamp_min(1)
    # where() keeps the gradient finite at var == 0, where sqrt's derivative is infinite
    std = torch.where(var > 0, var.clamp_min(torch.finfo(x.dtype).tiny).sqrt(), torch.zeros_like(var))
    return mean_shifted + x[:, 0], std


def standardize(x: torch.Tensor, mask: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """z-scores over valid steps, 0 at invalid steps and in constant channels."""
    z = (x - mean[:, None]) / torch.where(std > 0, std, torch.ones_like(std))[:, None]
    return z * (mask[..., None] & (std > 0)[:, None]).to(x.dtype)


def lagged_cross_correlation(zs: torch.Tensor, za: torch.Tensor, n: torch.Tensor, lags: int) -> torch.Tensor:
    """[N, L+1, S, A]: sum_t zs[t] za[t-l] / (n-1) for l = 0..L (zs, za zero past the valid steps)."""
    horizon = zs.shape[1]
    per_lag = [torch.einsum("nts,nta->nsa", zs[:, lag:], za[:, : horizon - lag]) for lag in range(lags + 1)]
    return torch.stack(per_lag, 1) / (n - 1).clamp_min(1).to(zs.dtype)[:, None, None, None]


class CorrelationSummarizer:
    """Output: cross-correlations [S*A*(L+1)], then mean and std of state features and actions."""

    def __init__(self, cfg: CorrelationConfig, state_differences: bool):
        self.cfg = cfg
        self.state_differences = state_differences

    def check(self, horizon: int) -> None:
        if self.cfg.lags >= horizon:
            raise ConfigError(f"summarizer lags={self.cfg.lags} must be shorter than the trajectory horizon {horizon}")

    def output_dim(self, state_dim: int, action_dim: int, horizon: int) -> int:
        return state_dim * action_dim * (self.cfg.lags + 1) + 2 * (state_dim + action_dim)

    def __call__(self, traj: Trajectories) -> torch.Tensor:
        self.check(traj.horizon)
        states = held_states(traj)
        feats = states[:, 1:] - states[:, :-1] if self.state_differences else states[:, :-1]
        mask, n = traj.valid, traj.valid.sum(1)
        s_mean, s_std = masked_moments(feats, mask)
        a_mean, a_std = masked_moments(traj.actions, mask)
        cross = lagged_cross_correlation(standardize(feats, mask, s_mean, s_std),
                                         standardize(traj.actions, mask, a_mean, a_std), n, self.cfg.lags)
        return torch.cat([cross.flatten(1), s_mean, s_std, a_mean, a_std], 1)


def corr(cfg: CorrelationConfig) -> CorrelationSummarizer:
    return CorrelationSummarizer(cfg, state_differences=False)


def corrdiff(cfg: CorrelationConfig) -> CorrelationSummarizer:
    return CorrelationSummarizer(cfg, state_differences=True)

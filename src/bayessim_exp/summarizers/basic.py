"""`start` (the first K steps) and `waypoints` (K evenly spaced times over the whole trajectory)."""

from __future__ import annotations

import dataclasses

import torch

from ..errors import ConfigError
from ..sim.trajectories import Trajectories
from .masking import held_states


@dataclasses.dataclass
class StepsConfig:
    steps: int  # K
    include_actions: bool

    def validate(self) -> None:
        if self.steps < 1:
            raise ConfigError(f"steps must be >= 1, got {self.steps}")


def evenly_spaced_times(horizon: int, count: int) -> torch.Tensor:
    """`count` state indices spread over 0..horizon inclusive, first and last included."""
    return torch.linspace(0, horizon, count).round().long()


class IndexSummarizer:
    """States (and actions) at chosen time indices, flattened; indices depend on the horizon."""

    def __init__(self, cfg: StepsConfig):
        self.cfg = cfg

    def check(self, horizon: int) -> None:
        if self.cfg.steps > horizon:
            raise ConfigError(f"summarizer steps={self.cfg.steps} exceeds the trajectory horizon {horizon}")

    def indices(self, horizon: int) -> torch.Tensor:
        raise NotImplementedError

    def output_dim(self, state_dim: int, action_dim: int, horizon: int) -> int:
        return self.cfg.steps * (state_dim + (action_dim if self.cfg.include_actions else 0))

    def __call__(self, traj: Trajectories) -> torch.Tensor:
        self.check(traj.horizon)
        idx = self.indices(traj.horizon).to(traj.states.device)
        parts = [held_states(traj)[:, idx].flatten(1)]
        if self.cfg.include_actions:
            acts = traj.actions[:, idx.clamp(max=traj.horizon - 1)] * traj.valid[:, idx.clamp(max=traj.horizon - 1), None]
            parts.append(acts.flatten(1))
        return torch.cat(parts, 1)


class StartSummarizer(IndexSummarizer):
    def indices(self, horizon: int) -> torch.Tensor:
        return torch.arange(self.cfg.steps)


class WaypointsSummarizer(IndexSummarizer):
    def indices(self, horizon: int) -> torch.Tensor:
        # actions at the last time clamp to T-1
        return evenly_spaced_times(horizon, self.cfg.steps)

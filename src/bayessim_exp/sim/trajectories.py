"""Trajectories: the batch of rollouts every summarizer and the pipeline consume."""

from __future__ import annotations

import dataclasses

import torch


@dataclasses.dataclass
class Trajectories:
    """N rollouts of T control steps.

    states:   [N, T+1, S] observations, states[:, t] is seen before actions[:, t]
    actions:  [N, T, A]   normalised actions in [-1, 1]
    rewards:  [N, T]
    valid:    [N, T] bool, False after an episode terminated (the step and what follows
              carry the last valid values and must be masked by consumers)
    diverged: [N] bool, the simulation became non-finite or MuJoCo raised; such rows are
              excluded from training and counted
    dt:       control timestep in seconds
    """

    states: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    valid: torch.Tensor
    diverged: torch.Tensor
    dt: float

    def __post_init__(self) -> None:
        n, t1, _ = self.states.shape
        if self.actions.shape[:2] != (n, t1 - 1):
            raise ValueError(f"actions {tuple(self.actions.shape)} do not match states {tuple(self.states.shape)}")
        if self.valid.shape != (n, t1 - 1) or self.rewards.shape != (n, t1 - 1):
            raise ValueError("rewards and valid must be [N, T]")
        if self.diverged.shape != (n,):
            raise ValueError("diverged must be [N]")

    @property
    def num(self) -> int:
        return self.states.shape[0]

    @property
    def horizon(self) -> int:
        return self.actions.shape[1]

    def select(self, index: torch.Tensor) -> Trajectories:
        return Trajectories(
            self.states[index], self.actions[index], self.rewards[index], self.valid[index],
            self.diverged[index], self.dt,
        )

    def truncate(self, horizon: int) -> Trajectories:
        if horizon > self.horizon:
            raise ValueError(f"cannot truncate {self.horizon} steps to {horizon}")
        return Trajectories(
            self.states[:, : horizon + 1], self.actions[:, :horizon], self.rewards[:, :horizon],
            self.valid[:, :horizon], self.diverged, self.dt,
        )

    def to(self, device: torch.device | str) -> Trajectories:
        return Trajectories(
            *(getattr(self, f.name).to(device) for f in dataclasses.fields(self) if f.name != "dt"),
            dt=self.dt,
        )

    def state_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @staticmethod
    def cat(parts: list[Trajectories]) -> Trajectories:
        """The rows of every part, each field on the first part's device for it: sim=mjx and sim=auto on a GPU run
        batches below `native_below` on native MuJoCo, so a collect's small part of exact replays comes back on the
        CPU beside its GPU part."""
        fields = [f.name for f in dataclasses.fields(Trajectories) if f.name != "dt"]
        return Trajectories(
            *(torch.cat([getattr(p, name).to(getattr(parts[0], name).device) for p in parts]) for name in fields),
            dt=parts[0].dt,
        )

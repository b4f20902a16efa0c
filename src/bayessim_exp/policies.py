"""Collect policies: batched `act(obs [N, S], t) -> actions [N, A]` in [-1, 1]."""

from __future__ import annotations

import dataclasses

import torch

from .registry import register


@dataclasses.dataclass
class RandomPolicyConfig:
    pass


class RandomPolicy:
    """Independent uniform actions over the normalised bounds at every step."""

    def __init__(self, action_dim: int, seed: int):
        self.action_dim = action_dim
        self.generator = torch.Generator().manual_seed(seed)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.rand(obs.shape[0], self.action_dim, generator=self.generator) * 2 - 1

    def open_loop_actions(self, n: int, horizon: int) -> torch.Tensor:
        """The actions [n, horizon, A] that `horizon` calls of act() would give (the observations are
        never read), so a simulator can run the whole rollout in one compiled loop."""
        dummy = torch.empty(n, 0)
        return torch.stack([self.act(dummy, t) for t in range(horizon)], 1)


@register("policy", "random", RandomPolicyConfig)
def random_policy(cfg: RandomPolicyConfig, action_dim: int, seed: int) -> RandomPolicy:
    return RandomPolicy(action_dim, seed)


class OpenLoopPolicy:
    """Recorded actions [N, T, A] played step by step, whatever the observations (replaying real
    trajectories in simulation)."""

    def __init__(self, actions: torch.Tensor):
        self.actions = actions

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[:, t].to(obs.device)

"""Collect policies `rl` and `rl_randomized`: a trained torchrl actor's mean action (their configs are
in policies.py, so that checking a config does not import torchrl)."""

from __future__ import annotations

import logging

import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ..policies import Policy, RandomizedRLPolicyConfig, RandomPolicy, RLPolicyConfig

log = logging.getLogger(__name__)


class ActorPolicy(Policy):
    """A trained torchrl actor's mean action; with probability `random_share` a slot's action is uniform instead."""

    def __init__(self, actor, action_dim: int, seed: int, random_share: float):
        self.actor, self.random_share = actor, random_share
        self.random = RandomPolicy(action_dim, seed)
        # where the actor's weights live; the simulator's observations may live elsewhere (None: a
        # parameter-free actor, which acts where the observations are)
        first = next(actor.parameters(), None) if isinstance(actor, torch.nn.Module) else None
        self.device = None if first is None else first.device

    @torch.no_grad()
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        device = self.device or obs.device
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            td = self.actor(TensorDict({"observation": obs.float().to(device)}, batch_size=obs.shape[:1], device=device))
        action = td["action"].clamp(-1.0, 1.0)
        if self.random_share > 0:
            explore = (torch.rand(obs.shape[0], generator=self.random.generator) < self.random_share).to(device)
            action = torch.where(explore[:, None], self.random.act(obs, t).to(action), action)
        return action


def actor_policy(actor, action_dim: int, seed: int, random_share: float, name: str):
    if actor is None:
        log.info("policy=%s: no trained actor yet (first round, or rl=none): uniform random actions", name)
        return RandomPolicy(action_dim, seed)
    return ActorPolicy(actor, action_dim, seed, random_share)


def rl_policy(cfg: RLPolicyConfig, action_dim: int, seed: int, actor=None, **_: object):
    return actor_policy(actor, action_dim, seed, 0.0, "rl")


def rl_randomized_policy(cfg: RandomizedRLPolicyConfig, action_dim: int, seed: int, actor=None, **_: object):
    return actor_policy(actor, action_dim, seed, cfg.random_share, "rl_randomized")

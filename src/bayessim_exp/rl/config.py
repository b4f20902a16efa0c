"""rl=ppo's typed config (defaults: conf/rl/ppo.yaml).

Kept apart from the component so that checking a config does not import torchrl (seconds): torchrl
loads only when a run really builds rl=ppo (registry: the factory is rl.component:ppo_component).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

from ..errors import ConfigError


@dataclasses.dataclass
class PPOConfig:
    """PPO's hyperparameters (defaults: conf/rl/ppo.yaml; a task's own values: conf/rl_task/ppo_<Task>.yaml)."""

    num_envs: int  # parallel simulator slots
    rollout_steps: int  # steps per slot between updates
    total_steps: int  # environment steps per train call (a round)
    epochs: int  # passes over each batch
    minibatch_size: int
    lr: float
    gamma: float
    gae_lambda: float
    clip_epsilon: float
    entropy_coeff: float
    reward_scale: float  # rewards are multiplied by this for the critic and advantages (returns reported unscaled)
    critic_coeff: float
    max_grad_norm: float
    hidden: list[int]
    init_log_std: float  # log std of the Gaussian actor at initialisation
    obs_clip: float  # normalised observations are clipped to +-obs_clip
    collector: Literal["auto", "compiled", "stepwise"]  # compiled: the actor inside MJX's compiled rollout; stepwise: torchrl's Collector

    def validate(self) -> None:
        if min(self.num_envs, self.rollout_steps, self.epochs, self.minibatch_size) < 1 or not self.hidden:
            raise ConfigError("num_envs, rollout_steps, epochs and minibatch_size must be >= 1, hidden non-empty")
        if self.total_steps < self.num_envs * self.rollout_steps:
            raise ConfigError(f"total_steps={self.total_steps} is less than one batch "
                              f"(num_envs x rollout_steps = {self.num_envs * self.rollout_steps})")
        if not (0 < self.gamma <= 1 and 0 <= self.gae_lambda <= 1 and self.clip_epsilon > 0 and self.lr > 0):
            raise ConfigError("need 0 < gamma <= 1, 0 <= gae_lambda <= 1, clip_epsilon > 0, lr > 0")


@dataclasses.dataclass
class EvaluateConfig:
    episodes: int  # surrogate-real episodes per round
    video_steps: int  # control steps in the GIF (0: no video)
    video_size: int  # pixels, square


@dataclasses.dataclass
class PPOComponentConfig:
    train_on: Literal["posterior", "prior", "nominal"]
    finetune: bool  # continue the previous round's policy instead of starting afresh
    train: PPOConfig
    evaluate: EvaluateConfig

    def validate(self) -> None:
        if self.evaluate.episodes < 1 or self.evaluate.video_steps < 0 or self.evaluate.video_size < 16:
            raise ConfigError("need evaluate.episodes >= 1, evaluate.video_steps >= 0, evaluate.video_size >= 16")
        self.train.validate()

"""PPO with torchrl (Collector, GAE, ClipPPOLoss) on a SimulatorEnv, resumable from a state dict.

One `train` call collects `total_steps` environment steps (rounded down to whole batches) in batches of
num_envs x rollout_steps (on MJX compiled with the actor, rl/compiled_collection.py; elsewhere torchrl's
Collector steps SimulatorEnv); after each batch the observation normaliser takes the batch's statistics,
GAE computes advantages and the clipped objective is minimised for `epochs` passes over shuffled minibatches.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch
from torchrl.collectors import Collector
from torchrl.envs import TransformedEnv
from torchrl.envs.transforms import RewardSum
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from ..errors import ConfigError
from .compiled_collection import CompiledCollector, can_compile
from .config import PPOConfig
from .env import SimulatorEnv
from .networks import Agent


def make_agent(cfg: PPOConfig, obs_dim: int, action_dim: int, device: torch.device | str) -> Agent:
    return Agent(obs_dim, action_dim, cfg.hidden, cfg.obs_clip, cfg.init_log_std).to(device)


class PPOTrainer:
    """Networks, optimiser and loss of one policy; `train` improves it on an environment."""

    def __init__(self, cfg: PPOConfig, obs_dim: int, action_dim: int, device: torch.device | str = "cpu"):
        self.cfg = cfg
        self.agent = make_agent(cfg, obs_dim, action_dim, device)
        self.loss = ClipPPOLoss(self.agent.actor, self.agent.critic, clip_epsilon=cfg.clip_epsilon,
                                entropy_coeff=cfg.entropy_coeff, critic_coeff=cfg.critic_coeff,
                                normalize_advantage=True, loss_critic_type="smooth_l1")
        self.advantage = GAE(gamma=cfg.gamma, lmbda=cfg.gae_lambda, value_network=self.agent.critic,
                             average_gae=False)
        self.optim = torch.optim.Adam(self.loss.parameters(), lr=cfg.lr)
        self.steps_done = 0  # over every train call, for TensorBoard's x axis

    @property
    def actor(self):
        return self.agent.actor

    def state_dict(self) -> dict:
        return {"agent": self.agent.state_dict(), "optim": self.optim.state_dict(), "steps_done": self.steps_done}

    def load_state_dict(self, state: dict) -> None:
        self.agent.load_state_dict(state["agent"])  # moved to the agent's device
        self.optim.load_state_dict(state["optim"])
        self.steps_done = state["steps_done"]

    def train(self, env: SimulatorEnv, seed: int, on_batch: Callable[[int, dict], None] | None = None) -> dict:
        """PPO for cfg.total_steps steps of `env`; returns the training curve (steps, mean episode return)."""
        collector = self._collector(env, seed)
        curve: dict[str, list[float]] = {"steps": [], "episode_return": [], "seconds": [], "update_seconds": []}
        t0 = time.perf_counter()
        for batch in collector:
            t_update = time.perf_counter()
            self.agent.norm.update(batch["observation"])
            stats = self._update(batch, seed + self.steps_done)
            curve["update_seconds"].append(time.perf_counter() - t_update)
            self.steps_done += batch.numel()
            done = batch["next", "done"]
            if done.any():
                stats["episode_return"] = float(batch["next", "episode_reward"][done].mean())
            curve["steps"].append(self.steps_done)
            curve["episode_return"].append(stats.get("episode_return", float("nan")))
            curve["seconds"].append(time.perf_counter() - t0)
            if on_batch is not None:
                on_batch(self.steps_done, stats)
        collector.shutdown()
        return curve

    def _collector(self, env: SimulatorEnv, seed: int):
        """The compiled collection where the simulator runs closed loops (cfg.collector: auto or compiled),
        torchrl's Collector over the environment otherwise; both seeded before their first reset."""
        cfg = self.cfg
        batch_frames = env.batch_size.numel() * cfg.rollout_steps
        total = cfg.total_steps // batch_frames * batch_frames
        compiled = can_compile(env)
        if cfg.collector == "compiled" and not compiled:
            raise ConfigError("rl.train.collector=compiled needs sim=mjx (or sim=auto on a GPU) and a task whose "
                              "resets are computed on the device; use collector=auto or stepwise")
        if compiled and cfg.collector != "stepwise":
            return CompiledCollector(env, self.agent, cfg.rollout_steps, total, seed)
        env.set_seed(seed)
        return Collector(TransformedEnv(env, RewardSum()), self.agent.actor, frames_per_batch=batch_frames,
                         total_frames=total, auto_register_policy_transforms=False)  # a feed-forward policy needs none

    def _update(self, batch, seed: int) -> dict:
        cfg = self.cfg
        batch["next", "reward"] = batch["next", "reward"] * cfg.reward_scale  # value targets of order one
        with torch.no_grad():
            self.advantage(batch)
        # only what the clipped objective reads: each minibatch gathers these rows (GAE wrote the last two)
        flat = batch.select("observation", "action", "action_log_prob", "advantage", "value_target").reshape(-1)
        generator = torch.Generator().manual_seed(seed)
        # summed where the losses are: a float() per minibatch would wait for the GPU three times per update
        sums = dict.fromkeys(("loss_objective", "loss_critic", "loss_entropy"), 0.0)
        updates = 0
        for _ in range(cfg.epochs):
            order = torch.randperm(flat.numel(), generator=generator)
            for start in range(0, flat.numel(), cfg.minibatch_size):
                losses = self.loss(flat[order[start : start + cfg.minibatch_size]])
                total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
                self.optim.zero_grad()
                total.backward()
                torch.nn.utils.clip_grad_norm_(self.loss.parameters(), cfg.max_grad_norm)
                self.optim.step()
                for k in sums:
                    sums[k] += losses[k].detach()
                updates += 1
        return {k: float(v) / updates for k, v in sums.items()}

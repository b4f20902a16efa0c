"""rl=ppo: each round trains PPO on simulators randomized with the round's distribution, then evaluates
the policy on the surrogate real system.

Stages (run by the pipeline after the round's score stage, each saved as round_NNN/<name>.pt):
  train_policy  PPO for rl.train.total_steps steps on `train_on` (posterior | prior | nominal); with
                `finetune` it continues the previous round's policy, optimiser and normaliser
  evaluate      returns of the deterministic policy on the surrogate real parameters (mean/min/max into
                results.json and TensorBoard) and a GIF of one episode (skipped, with the reason logged,
                without OpenGL)

`train_on=prior` is the uniform domain-randomization baseline and `nominal` trains on the MJCF's own
parameters, so the posterior-vs-prior-vs-nominal comparison is one sweep over rl.train_on.

It is built with what it uses (the task, simulator pool, device, prior, the real data source's true
parameters and `distribution(ctx)`, the round's distribution: in a pipeline the inference method's posterior)
and reads from the round's context (stages.RoundContext) only the seed, earlier artifacts and the TensorBoard
logger.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch

from ..distributions.base import ParameterDistribution
from ..errors import ConfigError
from ..sim.pool import SimulatorPool
from ..stages import RoundContext, Stage
from ..tasks.base import Task
from .actor_policy import ActorPolicy
from .config import PPOComponentConfig
from .env import SimulatorEnv, distribution_sampler, fixed_params
from .evaluate import episode_returns, summary
from .ppo import PPOTrainer, make_agent
from .video import render_gif

log = logging.getLogger(__name__)


class PPOComponent:
    def __init__(self, cfg: PPOComponentConfig, task: Task, sims: SimulatorPool, device: torch.device,
                 prior: ParameterDistribution, true_params: np.ndarray | None,
                 distribution: Callable[[RoundContext], ParameterDistribution]):
        self.cfg, self.task, self.sims, self.device, self.prior = cfg, task, sims, device, prior
        self.true_params, self.distribution = true_params, distribution
        self.train_cfg = cfg.train

    def stages(self) -> list[Stage]:
        # train_policy reads the round's distribution through `distribution`, not an artifact
        return [Stage("train_policy", self.train_policy), Stage("evaluate", self.evaluate, inputs=("train_policy",))]

    def trainer(self, state: dict | None = None) -> PPOTrainer:
        trainer = PPOTrainer(self.train_cfg, self.task.obs_dim, self.task.action_dim, self.device)
        if state is not None:
            trainer.load_state_dict(state)
        return trainer

    def sampler(self, ctx: RoundContext):
        if self.cfg.train_on == "nominal":
            return fixed_params(self.task.spec.nominal)
        return distribution_sampler(self.prior if self.cfg.train_on == "prior" else self.distribution(ctx))

    def train_policy(self, ctx: RoundContext) -> dict:
        previous = ctx.output("train_policy", ctx.round - 1) if self.cfg.finetune and ctx.round > 1 else None
        if previous is not None:
            log.info("round %d: PPO continues round %d's policy", ctx.round, ctx.round - 1)
        with torch.random.fork_rng():
            torch.manual_seed(ctx.seed)  # network initialisation and action sampling
            trainer = self.trainer(None if previous is None else previous["trainer"])
            env = SimulatorEnv(self.sims.get(self.train_cfg.num_envs), self.sampler(ctx), ctx.seed,
                               draw_steps=self.train_cfg.rollout_steps)
            curve = trainer.train(env, ctx.seed, self._logger(ctx))
        log.info("round %d: PPO on %s, %d steps in %.1f s, last training episode return %.1f", ctx.round,
                 self.cfg.train_on, curve["steps"][-1], curve["seconds"][-1], _last_finite(curve["episode_return"]))
        return {"trainer": trainer.state_dict(), "curve": curve}

    def _logger(self, ctx: RoundContext):
        def on_batch(steps: int, stats: dict) -> None:
            for key, value in stats.items():
                ctx.tb.scalar(f"rl_round_{ctx.round:03d}/{key}", value, steps)

        return on_batch

    def actor(self, ctx: RoundContext) -> torch.nn.Module | None:
        """The latest trained actor at this point of the round (None before the first train_policy)."""
        for r in range(ctx.round, 0, -1):
            if ctx.has("train_policy", r):
                return self._actor(ctx.output("train_policy", r)["trainer"])
        return None

    def _actor(self, state: dict) -> torch.nn.Module:
        """The trained actor alone: loss, advantage and optimiser are only for training (and this runs at
        every collect-policy build)."""
        agent = make_agent(self.train_cfg, self.task.obs_dim, self.task.action_dim, self.device)
        agent.load_state_dict(state["agent"])
        return agent.actor

    def evaluate(self, ctx: RoundContext) -> dict:
        if self.true_params is None:
            log.warning("round %d: the real data source has no true parameters: no surrogate-real evaluation", ctx.round)
            return {"summary": None, "video": None}
        actor = self._actor(ctx.output("train_policy")["trainer"])
        e = self.cfg.evaluate
        returns = episode_returns(actor, self.sims.get(e.episodes), self.true_params, ctx.seed)
        out = {"returns": returns, "summary": summary(returns), "video": None}
        if e.video_steps:
            policy = ActorPolicy(actor, self.task.action_dim, ctx.seed, random_share=0.0)
            out["video"], why = render_gif(self.task, self.true_params, policy, e.video_steps, e.video_size, ctx.seed)
            if out["video"] is None:
                log.warning("round %d: no video of the policy: %s", ctx.round, why)
        if out["video"] is not None:  # the returns reach TensorBoard through record()
            ctx.tb.image("rl/surrogate_real_video", out["video"], ctx.round)
        log.info("round %d: surrogate real return %.1f (min %.1f, max %.1f) over %d episodes", ctx.round,
                 out["summary"]["mean"], out["summary"]["min"], out["summary"]["max"], e.episodes)
        return out

    def record(self, ctx: RoundContext) -> dict:
        """This round's fields of results.json."""
        curve = ctx.output("train_policy")["curve"]
        return {"surrogate_real_return": ctx.output("evaluate")["summary"],
                "rl_training": {"train_on": self.cfg.train_on, "steps": curve["steps"][-1],
                                "seconds": round(curve["seconds"][-1], 3),
                                "last_episode_return": _last_finite(curve["episode_return"])}}


def ppo_component(cfg: PPOComponentConfig, task: Task, sims: SimulatorPool, device: torch.device,
                  prior: ParameterDistribution, true_params: np.ndarray | None,
                  distribution: Callable[[RoundContext], ParameterDistribution]) -> PPOComponent:
    """The networks train on `device`; true_params: the real data source's, for the surrogate-real evaluation."""
    if not task.has_reward:
        raise ConfigError(f"rl=ppo trains on the task's reward, and task={task.name} defines none: give the "
                          "task a reward (task=mjcf: its `reward` key), or run without RL (rl=none)")
    return PPOComponent(cfg, task, sims, device, prior, true_params, distribution)


def _last_finite(values: list[float]) -> float | None:
    finite = [v for v in values if np.isfinite(v)]
    return finite[-1] if finite else None

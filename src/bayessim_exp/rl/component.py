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

It reads from the round's context (stages.RoundContext): the seed, earlier artifacts, the TensorBoard
logger and the run's components (simulator pool, prior, the inference method's posterior, the real
data source's true parameters).
"""

from __future__ import annotations

import logging

import numpy as np
import torch

from ..errors import ConfigError
from ..stages import RoundContext, Stage
from .actor_policy import ActorPolicy
from .config import PPOComponentConfig
from .env import SimulatorEnv, distribution_sampler, fixed_params
from .evaluate import episode_returns, summary
from .ppo import PPOTrainer, make_agent
from .video import render_gif

log = logging.getLogger(__name__)


class PPOComponent:
    def __init__(self, cfg: PPOComponentConfig, comp):
        self.cfg, self.task, self.device = cfg, comp.task, comp.device
        self.train_cfg = cfg.train

    def stages(self) -> list[Stage]:
        # train_policy reads the round's distribution through the inference method, not an artifact
        return [Stage("train_policy", self.train_policy), Stage("evaluate", self.evaluate, inputs=("train_policy",))]

    def trainer(self, state: dict | None = None) -> PPOTrainer:
        trainer = PPOTrainer(self.train_cfg, self.task.obs_dim, self.task.action_dim, self.device)
        if state is not None:
            trainer.load_state_dict(state)
        return trainer

    def sampler(self, ctx: RoundContext):
        if self.cfg.train_on == "nominal":
            return fixed_params(self.task.spec.nominal)
        return distribution_sampler(ctx.comp.prior if self.cfg.train_on == "prior" else ctx.comp.method.posterior(ctx))

    def train_policy(self, ctx: RoundContext) -> dict:
        previous = ctx.output("train_policy", ctx.round - 1) if self.cfg.finetune and ctx.round > 1 else None
        if previous is not None:
            log.info("round %d: PPO continues round %d's policy", ctx.round, ctx.round - 1)
        with torch.random.fork_rng():
            torch.manual_seed(ctx.seed)  # network initialisation and action sampling
            trainer = self.trainer(None if previous is None else previous["trainer"])
            env = SimulatorEnv(ctx.comp.sims.get(self.train_cfg.num_envs), self.sampler(ctx), ctx.seed)
            curve = trainer.train(env, ctx.seed, self._logger(ctx))
        log.info("round %d: PPO on %s, %d steps in %.1f s, last training episode return %.1f", ctx.round,
                 self.cfg.train_on, curve["steps"][-1], curve["seconds"][-1], _last_finite(curve["episode_return"]))
        return {"trainer": trainer.state_dict(), "curve": curve}

    def _logger(self, ctx: RoundContext):
        if ctx.tb is None:
            return None

        def on_batch(steps: int, stats: dict) -> None:
            for key, value in stats.items():
                ctx.tb.writer.add_scalar(f"rl_round_{ctx.round:03d}/{key}", value, steps)

        return on_batch

    def actor(self, ctx: RoundContext):
        """The latest trained actor at this point of the round (None before the first train_policy)."""
        for r in range(ctx.round, 0, -1):
            if ctx.has("train_policy", r):
                return self._actor(ctx.output("train_policy", r)["trainer"])
        return None

    def _actor(self, state: dict):
        """The trained actor alone: loss, advantage and optimiser are only for training (and this runs at
        every collect-policy build)."""
        agent = make_agent(self.train_cfg, self.task.obs_dim, self.task.action_dim, self.device)
        agent.load_state_dict(state["agent"])
        return agent.actor

    def evaluate(self, ctx: RoundContext) -> dict:
        real_params = ctx.comp.real.true_params
        if real_params is None:
            log.warning("round %d: the real data source has no true parameters: no surrogate-real evaluation", ctx.round)
            return {"summary": None, "video": None}
        actor = self._actor(ctx.output("train_policy")["trainer"])
        e = self.cfg.evaluate
        returns = episode_returns(actor, ctx.comp.sims.get(e.episodes), real_params, ctx.seed)
        out = {"returns": returns, "summary": summary(returns), "video": None}
        if e.video_steps:
            policy = ActorPolicy(actor, self.task.action_dim, ctx.seed, random_share=0.0)
            out["video"], why = render_gif(self.task, real_params, policy, e.video_steps, e.video_size, ctx.seed)
            if out["video"] is None:
                log.warning("round %d: no video of the policy: %s", ctx.round, why)
        if ctx.tb is not None and out["video"] is not None:  # the returns reach TensorBoard through record()
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


def ppo_component(cfg: PPOComponentConfig, comp, **_: object):
    """comp: the run's Components; the networks train on the run's `device`."""
    if not comp.task.has_reward:
        raise ConfigError(f"rl=ppo trains on the task's reward, and task={comp.task.name} defines none: give the "
                          "task a reward (task=mjcf: its `reward` key), or run without RL (rl=none)")
    return PPOComponent(cfg, comp)


def _last_finite(values: list[float]) -> float | None:
    finite = [v for v in values if np.isfinite(v)]
    return finite[-1] if finite else None

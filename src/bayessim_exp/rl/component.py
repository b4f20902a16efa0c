"""rl=ppo: each round trains PPO on simulators randomized with the round's distribution, then evaluates
the policy on the surrogate real system.

Stages (run by the pipeline after the round's condition stage, each saved as round_NNN/<name>.pt):
  train_policy  PPO for rl.train.total_steps steps on `train_on` (posterior | prior | nominal); with
                `finetune` it continues the previous round's policy, optimiser and normaliser
  evaluate      returns of the deterministic policy on the surrogate real parameters (mean/min/max into
                results.json and TensorBoard) and a GIF of one episode (skipped, with the reason logged,
                without OpenGL)

`train_on=prior` is the uniform domain-randomization baseline and `nominal` trains on the MJCF's own
parameters, so the posterior-vs-prior-vs-nominal comparison is one sweep over rl.train_on.

The component needs from the pipeline a round context (`RoundContext`): the round, the stage's seed,
the task, the simulator pool, the surrogate real parameters, the prior, the round's posterior, earlier
stages' outputs and the TensorBoard logger.
"""

from __future__ import annotations

import logging
from typing import Any, Callable, NamedTuple, Protocol

import numpy as np
import torch

from ..sim.pool import SimulatorPool
from ..tasks.base import Task
from .config import PPOComponentConfig
from .env import SimulatorEnv, distribution_sampler, fixed_params
from .evaluate import episode_returns, summary
from .ppo import PPOTrainer

log = logging.getLogger(__name__)


class RoundContext(Protocol):
    round: int  # 1-based
    seed: int  # this stage's seed (derived from the run seed, the round and the stage's name)
    task: Task
    sims: SimulatorPool
    real_params: np.ndarray  # [D], the surrogate real system's parameters
    prior: Any  # distributions with .sample((n,)) -> float64 [n, D]
    tb: Any  # TensorBoardLogger, or None

    def posterior(self) -> Any: ...

    def output(self, stage: str, round: int | None = None) -> dict | None:
        """A finished stage's artifact (this round when round is None), None if it has not run."""


class StageSpec(NamedTuple):
    name: str
    run: Callable[[RoundContext], dict]
    inputs: tuple[str, ...]  # stages of the same round whose outputs `run` reads


class PPOComponent:
    def __init__(self, cfg: PPOComponentConfig, task: Task, device: str):
        self.cfg, self.task, self.device = cfg, task, torch.device(device)
        self.train_cfg = cfg.train

    def stages(self) -> list[StageSpec]:
        needs = ("condition",) if self.cfg.train_on == "posterior" else ()  # the stage that gives the posterior
        return [StageSpec("train_policy", self.train_policy, needs),
                StageSpec("evaluate", self.evaluate, ("train_policy",))]

    def trainer(self, state: dict | None = None) -> PPOTrainer:
        trainer = PPOTrainer(self.train_cfg, self.task.obs_dim, self.task.action_dim, self.device)
        if state is not None:
            trainer.load_state_dict(state)
        return trainer

    def sampler(self, ctx: RoundContext):
        if self.cfg.train_on == "nominal":
            return fixed_params(self.task.spec.nominal)
        return distribution_sampler(ctx.prior if self.cfg.train_on == "prior" else ctx.posterior())

    def train_policy(self, ctx: RoundContext) -> dict:
        previous = ctx.output("train_policy", ctx.round - 1) if self.cfg.finetune and ctx.round > 1 else None
        with torch.random.fork_rng():
            torch.manual_seed(ctx.seed)  # network initialisation and action sampling
            trainer = self.trainer(None if previous is None else previous["trainer"])
            env = SimulatorEnv(ctx.sims.get(self.train_cfg.num_envs), self.sampler(ctx), ctx.seed)
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
            trained = ctx.output("train_policy", r)
            if trained is not None:
                return self.trainer(trained["trainer"]).actor
        return None

    def evaluate(self, ctx: RoundContext) -> dict:
        from ..policies import ActorPolicy
        from .video import render_gif

        actor = self.trainer(ctx.output("train_policy")["trainer"]).actor
        e = self.cfg.evaluate
        returns = episode_returns(actor, ctx.sims.get(e.episodes), ctx.real_params, ctx.seed)
        out = {"returns": returns, "summary": summary(returns), "video": None}
        if e.video_steps:
            policy = ActorPolicy(actor, self.task.action_dim, ctx.seed, random_share=0.0)
            out["video"], why = render_gif(self.task, ctx.real_params, policy, e.video_steps, e.video_size, ctx.seed)
            if out["video"] is None:
                log.warning("round %d: no video of the policy: %s", ctx.round, why)
        if ctx.tb is not None:
            ctx.tb.scalars(ctx.round, {f"rl/surrogate_real_return_{k}": v for k, v in out["summary"].items()})
            if out["video"] is not None:
                ctx.tb.gif("rl/surrogate_real_video", out["video"], ctx.round)
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


def _last_finite(values: list[float]) -> float | None:
    finite = [v for v in values if np.isfinite(v)]
    return finite[-1] if finite else None

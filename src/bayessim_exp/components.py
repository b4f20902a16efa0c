"""Every component of a run, built and checked from the config before anything is simulated."""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
from omegaconf import DictConfig

from . import registry
from .distributions.base import ParameterDistribution
from .errors import ConfigError
from .inference.base import InferenceMethod
from .real import RealSource
from .rl.base import RLComponent
from .run_config import RunConfig
from .sim.pool import SimulatorPool
from .sim.trajectories import Trajectories
from .summarizers.base import Summarizer
from .tasks.base import Task


@dataclasses.dataclass
class Components:
    cfg: DictConfig
    rc: RunConfig
    task: Task
    prior: ParameterDistribution
    sims: SimulatorPool
    summarizer: Summarizer
    real: RealSource
    x_dim: int
    method: InferenceMethod | None = None  # built last: a method may use every other component
    rl: RLComponent | None = None  # None: rl=none

    @property
    def device(self) -> torch.device:
        return torch.device(self.rc.device)

    def policy(self, seed: int, ctx=None):
        """The collect policy, seeded; within a round (ctx) `rl`/`rl_randomized` act with the latest trained
        actor and `replay` replays the real trajectories recorded so far."""
        actor = self.rl.actor(ctx) if self.rl is not None and ctx is not None else None
        recorded = Trajectories(**ctx.output("real")["traj"]) if ctx is not None and ctx.has("real") else None
        return registry.build("policy", self.cfg.policy, action_dim=self.task.action_dim, seed=seed,
                              control_dt=self.task.cfg.control_dt, actor=actor, recorded=recorded, task=self.task)

    def model(self):
        """A fresh posterior model q(theta | x) for this task and summarizer."""
        deps: dict[str, Any] = {"theta_dim": self.task.spec.dim, "x_dim": self.x_dim}
        if getattr(self.summarizer, "embedding", None) is not None:
            deps["embedding"] = self.summarizer.embedding
        return registry.build("model", self.cfg.model, **deps)


def build_components(cfg: DictConfig, rc: RunConfig) -> Components:
    """Build and check every component; all config errors surface here, before any simulation."""
    for group in registry.GROUPS:
        if group not in cfg:
            raise ConfigError(f"config has no {group!r} group; allowed: {', '.join(registry.names(group))}")
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, rc.collect.chunk)
    summarizer = registry.build("summarizer", cfg.summarizer)
    summarizer.check(rc.collect.horizon)
    x_dim = summarizer.output_dim(task.obs_dim, task.action_dim, rc.collect.horizon)
    registry.parse_params("policy", cfg.policy)
    registry.parse_params("model", cfg.model)
    real = registry.build("real", cfg.real, task=task, sims=sims, prior=prior, seed=rc.seed)
    real.check(rc.collect.horizon)
    if rc.logging.plot_params is not None:
        task.spec.subset(rc.logging.plot_params)
    comp = Components(cfg, rc, task, prior, sims, summarizer, real, x_dim)
    comp.rl = registry.build("rl", cfg.rl, comp=comp)
    comp.method = registry.build("method", cfg.method, comp=comp)
    return comp

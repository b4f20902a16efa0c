"""A run's objects, built and checked from the config before anything is simulated, and the pieces that wire them.

The pipeline (like StandaloneRounds and the benchmarks) builds these and hands each object to what uses it:
the RL component gets the round's distribution as a callable, the inference method a MethodInputs, the collect
policy the RL component's actor. Components is only the build's result, unpacked here: no stage sees it.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING

import torch
from omegaconf import DictConfig

from . import registry
from .distributions.base import ParameterDistribution
from .errors import ConfigError
from .inference.base import InferenceMethod, MethodInputs, PolicyFactory
from .machine import fit_to_machine
from .models.base import PosteriorModel
from .policies import Policy, as_policy
from .real import RealSource
from .run_config import RunConfig
from .sim import integrators
from .sim.pool import SimulatorPool
from .sim.trajectories import Trajectories
from .stages import RoundContext
from .summarizers.base import Summarizer
from .tasks.base import Task

if TYPE_CHECKING:
    from .rl.base import RLComponent


def _no_actor(ctx: RoundContext) -> torch.nn.Module | None:
    return None


@dataclasses.dataclass(frozen=True)
class CollectPolicies:
    """The collect policy, seeded; within a round (ctx) `rl`/`rl_randomized` act with `actor(ctx)`, the RL
    component's latest trained actor, and `replay` replays the real trajectories recorded so far."""

    build: Callable[..., Policy]  # the policy option's factory, its config parsed once
    task: Task
    actor: Callable[[RoundContext], torch.nn.Module | None] = _no_actor

    def __call__(self, seed: int, ctx: RoundContext | None = None) -> Policy:
        actor = self.actor(ctx) if ctx is not None else None
        recorded = Trajectories(**ctx.output("real")["traj"]) if ctx is not None and ctx.has("real") else None
        return as_policy(self.build(action_dim=self.task.action_dim, seed=seed, control_dt=self.task.cfg.control_dt,
                                    actor=actor, recorded=recorded, task=self.task))


@dataclasses.dataclass(frozen=True)
class Components:
    """What a run simulates and observes; the RL component and the inference method are built from these."""

    cfg: DictConfig  # the config as run: the composed one with this machine's choices (machine.py)
    rc: RunConfig
    task: Task
    prior: ParameterDistribution
    sims: SimulatorPool
    summarizer: Summarizer
    real: RealSource
    x_dim: int  # the summarizer's output width for this task and horizon
    model: Callable[[], PosteriorModel]  # a fresh posterior model q(theta | x) for this task and summarizer
    policy: CollectPolicies  # without an actor: the pipeline gives it the RL component's
    integrators: tuple[str, ...]  # what the method's simulations alternate between (sim/integrators.py's for_run)

    @property
    def device(self) -> torch.device:
        return torch.device(self.rc.device)


def build_components(cfg: DictConfig, rc: RunConfig) -> Components:
    """Build and check every component but the RL component and the method (build_rl, the pipeline), after the
    config is checked against this machine."""
    cfg = fit_to_machine(cfg, rc)
    for group in registry.GROUPS:
        if group not in cfg:
            raise ConfigError(f"config has no {group!r} group; allowed: {', '.join(registry.names(group))}")
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, rc.collect.chunk)
    summarizer = registry.build("summarizer", cfg.summarizer)
    summarizer.check(rc.collect.horizon)
    x_dim = summarizer.output_dim(task.obs_dim, task.action_dim, rc.collect.horizon)
    policy = CollectPolicies(registry.factory("policy", cfg.policy), task)
    embedding = getattr(summarizer, "embedding", None)
    model = functools.partial(registry.factory("model", cfg.model), theta_dim=task.spec.dim, x_dim=x_dim,
                              **({} if embedding is None else {"embedding": embedding}))
    real = registry.build("real", cfg.real, task=task, sims=sims, prior=prior, seed=rc.seed)
    real.check(rc.collect.horizon)
    if rc.logging.plot_params is not None:
        task.spec.subset(rc.logging.plot_params)
    return Components(cfg, rc, task, prior, sims, summarizer, real, x_dim, model, policy,
                      integrators.for_run(cfg))


def build_rl(cfg: DictConfig, comp: Components,
             distribution: Callable[[RoundContext], ParameterDistribution]) -> RLComponent:
    """The RL component (rl=none: one without stages); `distribution(ctx)` is the round's distribution to train on."""
    return registry.build("rl", cfg.rl, task=comp.task, sims=comp.sims, device=comp.device, prior=comp.prior,
                          true_params=comp.real.true_params, distribution=distribution)


def build_method(cfg: DictConfig, comp: Components, policy: PolicyFactory) -> InferenceMethod:
    """The inference method, handed what it uses; `policy`: the collect policy (a pipeline's acts with the RL
    component's actor)."""
    # the method simulates in slots that alternate between comp.integrators; the real stage and RL keep the model's own
    inputs = MethodInputs(comp.task, comp.prior, comp.sims.alternating(comp.integrators), comp.summarizer, comp.rc,
                          comp.device, comp.model, policy)
    return registry.build("method", cfg.method, inputs=inputs)

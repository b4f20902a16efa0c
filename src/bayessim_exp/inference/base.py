"""The interface of an inference method: how a round turns simulations and real data into a new
distribution over the simulator's parameters.

The pipeline owns the loop, seeds, artifacts and logging; a method contributes

    stages()         the named stages of its round, run after the `real` stage (which records new
                     real trajectories, kept raw across rounds: `real_trajectories(ctx)`)
    proposal(ctx)    the distribution the round simulates parameters from
    posterior(ctx)   the new distribution after the round, from its artifacts (a ParameterDistribution:
                     scored, plotted and handed to domain randomization like any other)
    handed_on_round(ctx)  whose distribution posterior(ctx) is: the round's own (the default), an earlier
                     round's, or the prior's (0), where a check kept the round's own from being handed on
    record(ctx)      method-specific fields of the round's entry in results.json
    stop_reason(ctx) why the run must stop after this round (its results written), or None

Methods are a config group (`method=bayessim`); a researcher's own is registered with
`registry.register("method", name, ConfigDataclass)` on a factory `(cfg, inputs: MethodInputs) -> InferenceMethod`,
and with `posterior=` a reader `(ctx, prior)` of a finished round's distribution from its artifacts alone, which
`api.load_run(...).posterior()` uses without building simulators.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import torch

from ..distributions.base import ParameterDistribution
from ..sim.trajectories import Trajectories
from ..stages import RoundContext, Stage

if TYPE_CHECKING:
    from ..models.base import PosteriorModel
    from ..policies import Policy
    from ..run_config import RunConfig
    from ..sim.pool import SimulatorPool
    from ..summarizers.base import Summarizer
    from ..tasks.base import Task


class PolicyFactory(Protocol):
    def __call__(self, seed: int, ctx: RoundContext | None = None) -> Policy:
        """The collect policy, seeded; within a round (ctx) `rl`/`rl_randomized` act with the latest trained actor
        and `replay` replays the real trajectories recorded so far."""
        ...


@dataclasses.dataclass(frozen=True)
class MethodInputs:
    """What an inference method uses, built by the pipeline and handed to the method's factory."""

    task: Task
    prior: ParameterDistribution
    sims: SimulatorPool
    summarizer: Summarizer
    rc: RunConfig  # the run's settings (collect, diagnostics, logging)
    device: torch.device
    model: Callable[[], PosteriorModel]  # a fresh posterior model q(theta | x) for this task and summarizer
    policy: PolicyFactory


class InferenceMethod(abc.ABC):
    @abc.abstractmethod
    def stages(self) -> list[Stage]: ...

    @abc.abstractmethod
    def proposal(self, ctx: RoundContext) -> ParameterDistribution: ...

    @abc.abstractmethod
    def posterior(self, ctx: RoundContext) -> ParameterDistribution: ...

    def handed_on_round(self, ctx: RoundContext) -> int:
        return ctx.round

    def record(self, ctx: RoundContext) -> dict:
        return {}

    def stop_reason(self, ctx: RoundContext) -> str | None:
        return None

    def added_round(self, ctx: RoundContext) -> str | None:
        """Why the run goes on for one more round after ctx's, the last planned one (None: it ends there)."""
        return None


def handed_on_name(source: int) -> str:
    """What a round handed on, in words: round `source`'s posterior, or the prior for 0."""
    return "the prior" if source == 0 else f"round {source}'s posterior"


def real_trajectories(ctx: RoundContext) -> Trajectories:
    """Every real trajectory recorded up to and including this round."""
    return Trajectories(**ctx.output("real")["traj"])

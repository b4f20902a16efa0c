"""Collect policies: batched `act(obs [N, S], t) -> actions [N, A]` in [-1, 1].

Every factory is called as `factory(cfg, action_dim=, seed=, control_dt=, actor=, recorded=, task=)`;
`actor` is the RL component's latest trained actor (None before the first train_policy stage, or with
rl=none), `recorded` the real trajectories recorded so far (None before the first real stage) and
`task` the run's task. A policy of your own is such a factory, given to `registry.register` (README:
"Your own components"). `rl` and `rl_randomized` act with torchrl, so their factories are in
rl/actor_policy.py; their configs are here, where checking them loads no torchrl.

Every policy is a `Policy`, which declares what a policy may do beyond acting step by step, each member with
the default of one that only acts; a factory's object that is not one (a plugin's) is taken as such (`as_policy`).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import Literal

import numpy as np
import torch

from .errors import ConfigError


class Policy(abc.ABC):
    """Batched `act(obs [N, S], t) -> actions [N, A]` in [-1, 1], and the optional members simulators and stages
    read instead of probing for them."""

    # plan(n) -> (OpenLoopPolicy, initial states or None): how each of n simulations starts and is driven (ReplayPolicy);
    # SimulatorPool.rollout asks for it before simulating. None: act drives them from the given or drawn states
    plan: Callable[[int], tuple[OpenLoopPolicy, dict[str, np.ndarray] | None]] | None = None
    # open_loop_actions(n, horizon) -> [n, horizon, A]: the actions `horizon` calls of act would give, where they never
    # read the observations, so a simulator can run the whole rollout in one compiled loop. None: closed loop
    open_loop_actions: Callable[[int, int], torch.Tensor] | None = None

    @abc.abstractmethod
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor: ...

    def select(self, rows: torch.Tensor | slice) -> Policy:
        """The policy of some slots only (a chunk of a long rollout): itself where it acts on any rows it is given."""
        return self

    def without_noise(self) -> Policy | None:
        """The policy as the real data were driven, where it adds noise to them (ReplayPolicy); None where it adds none."""
        return None


class _Acting(Policy):
    """An object with `act` alone, as a Policy."""

    def __init__(self, acting):
        self.acting = acting

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.acting.act(obs, t)


def as_policy(policy) -> Policy:
    """A factory's policy; one that is no Policy (README, 'Your own components': an object with `act`) only acts."""
    return policy if isinstance(policy, Policy) else _Acting(policy)


class RandomPolicy(Policy):
    """Independent uniform actions over the normalised bounds at every step."""

    def __init__(self, action_dim: int, seed: int):
        self.action_dim = action_dim
        self.generator = torch.Generator().manual_seed(seed)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.rand(obs.shape[0], self.action_dim, generator=self.generator) * 2 - 1

    def open_loop_actions(self, n: int, horizon: int) -> torch.Tensor:
        dummy = torch.empty(n, 0)
        return torch.stack([self.act(dummy, t) for t in range(horizon)], 1)


@dataclasses.dataclass
class RandomPolicyConfig:
    pass


def random_policy(cfg: RandomPolicyConfig, action_dim: int, seed: int, **_: object) -> RandomPolicy:
    return RandomPolicy(action_dim, seed)


class OpenLoopPolicy(Policy):
    """Recorded actions [N, T, A] played step by step, whatever the observations (replaying real
    trajectories in simulation), row n in slot n."""

    def __init__(self, actions: torch.Tensor):
        self.actions = actions

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[:, t].to(obs.device)

    def open_loop_actions(self, n: int, horizon: int) -> torch.Tensor:
        if n != len(self.actions):
            raise ValueError(f"{len(self.actions)} recorded action sequences for {n} slots")
        return self.actions[:, :horizon]

    def select(self, rows: torch.Tensor | slice) -> OpenLoopPolicy:
        return OpenLoopPolicy(self.actions[rows])


@dataclasses.dataclass
class ReplayPolicyConfig:
    action_noise: float  # std of the Gaussian added to each recorded (normalised) action, then clipped

    def validate(self) -> None:
        if self.action_noise < 0:
            raise ConfigError(f"action_noise must be >= 0, got {self.action_noise}")


class ReplayPolicy(Policy):
    """Every simulation driven like a real trajectory: one drawn at random among the recorded ones, its
    initial state (where the task maps an observation to a state; else the task's reset distribution)
    and its actions, perturbed by `action_noise` so that the simulated summaries vary around the real
    ones rather than repeat them (docs/statistics.md, 'Simulations driven like the real system')."""

    def __init__(self, cfg: ReplayPolicyConfig, recorded, task, seed: int):
        self.cfg, self.recorded, self.task = cfg, recorded, task
        self.generator = torch.Generator().manual_seed(seed)

    def plan(self, n: int) -> tuple[OpenLoopPolicy, dict[str, np.ndarray] | None]:
        """For n simulations: the actions each replays and their initial states (None: the reset distribution)."""
        if self.recorded is None:
            raise ConfigError("policy=replay replays recorded real trajectories, and none is recorded yet: use it "
                              "with real data that carry their actions (real=file, real=lerobot, real=csv), or another "
                              "collect policy")
        which = torch.randint(self.recorded.num, (n,), generator=self.generator)
        actions = self.recorded.actions[which].float().cpu()
        if self.cfg.action_noise > 0:
            noise = torch.randn(actions.shape, generator=self.generator) * self.cfg.action_noise
            actions = (actions + noise).clamp(-1.0, 1.0)
        start = self.task.state_from_observation(self.recorded.states[which, 0].double().cpu().numpy())
        return OpenLoopPolicy(actions), start

    def without_noise(self) -> ReplayPolicy | None:
        """The recorded trajectories replayed as they were executed (no action noise): how the real data were
        driven, the pairs the posterior's spread is calibrated and checked on; the same seed. None where there is no
        noise to take away."""
        if self.cfg.action_noise == 0:
            return None
        return ReplayPolicy(dataclasses.replace(self.cfg, action_noise=0.0), self.recorded, self.task,
                            int(self.generator.initial_seed()))

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        raise ConfigError("policy=replay drives batches of simulations through SimulatorPool.rollout "
                          "(its plan fixes each simulation's start), not step by step")


def replay_policy(cfg: ReplayPolicyConfig, seed: int, recorded=None, task=None, **_: object) -> ReplayPolicy:
    return ReplayPolicy(cfg, recorded, task, seed)


@dataclasses.dataclass
class FixedPolicyConfig:
    """An open-loop signal per action dimension; each list has one entry (all dimensions) or action_dim."""

    signal: Literal["constant", "sine", "chirp"]
    offset: list[float]
    amplitude: list[float]
    frequency: list[float]  # Hz; a chirp's frequency at t = 0
    frequency_end: list[float]  # Hz; a chirp's frequency after sweep_seconds, when it starts again
    sweep_seconds: float
    phase: list[float]  # rad

    def validate(self) -> None:
        if self.sweep_seconds <= 0:
            raise ConfigError("sweep_seconds must be > 0")


class FixedPolicy(Policy):
    """offset + amplitude * sin(angle(t)): constant = offset + amplitude (phase unused), sine: 2 pi f t + phase,
    chirp: a linear frequency sweep + phase."""

    def __init__(self, cfg: FixedPolicyConfig, action_dim: int, control_dt: float):
        def per_dim(name: str) -> torch.Tensor:
            values = torch.tensor(getattr(cfg, name), dtype=torch.float64)
            if len(values) not in (1, action_dim):
                raise ConfigError(f"policy.{name} needs 1 or {action_dim} (action_dim) values, got {len(values)}")
            return values.expand(action_dim)

        self.signal, self.dt, self.sweep = cfg.signal, control_dt, cfg.sweep_seconds
        self.offset, self.amplitude, self.phase = per_dim("offset"), per_dim("amplitude"), per_dim("phase")
        self.f0, self.f1 = per_dim("frequency"), per_dim("frequency_end")

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        seconds = t * self.dt
        if self.signal == "constant":
            angle = torch.full_like(self.phase, np.pi / 2)
        elif self.signal == "sine":
            angle = 2 * np.pi * self.f0 * seconds + self.phase
        else:
            s = seconds % self.sweep
            angle = 2 * np.pi * (self.f0 * s + (self.f1 - self.f0) * s**2 / (2 * self.sweep)) + self.phase
        action = (self.offset + self.amplitude * torch.sin(angle)).clamp(-1.0, 1.0).float()
        return action.expand(obs.shape[0], -1)


def fixed_policy(cfg: FixedPolicyConfig, action_dim: int, control_dt: float, **_: object) -> FixedPolicy:
    return FixedPolicy(cfg, action_dim, control_dt)


@dataclasses.dataclass
class RLPolicyConfig:
    pass


@dataclasses.dataclass
class RandomizedRLPolicyConfig:
    random_share: float  # probability that a slot takes a uniform random action at a step

    def validate(self) -> None:
        if not 0.0 <= self.random_share <= 1.0:
            raise ConfigError(f"random_share must lie in [0, 1], got {self.random_share}")

"""A torchrl EnvBase over any Simulator: N slots, each drawing new physical parameters at its own reset.

Only the Simulator protocol is used (reset with per-slot parameters, step), so the same environment
runs on the native CPU backend and on MJX. The parameter source is a callable `(n, generator) ->
float64 [n, D]`: a posterior's or the prior's `sample`, or a fixed parameter vector (`fixed_params`).

A slot whose simulation diverged is reported as terminated: its observations are frozen and its
rewards zero, so bootstrapping from it would teach the critic a fiction; it restarts at the next reset.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data.tensor_specs import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from ..sim.base import Simulator

ParamSampler = Callable[[int, torch.Generator], torch.Tensor]


def distribution_sampler(distribution) -> ParamSampler:
    """Draws from any project distribution (prior, posterior): ParameterDistribution.sample takes the generator."""
    return lambda n, generator: distribution.sample((n,), generator=generator).double()


def fixed_params(values: np.ndarray | torch.Tensor) -> ParamSampler:
    """Every slot gets the same parameters (nominal or surrogate-real values)."""
    row = torch.as_tensor(np.asarray(values, dtype=np.float64))[None]
    return lambda n, generator: row.expand(n, -1).clone()


class SimulatorEnv(EnvBase):
    """Batched environment of `sim.num_envs` slots; keys: observation, action, reward, done/terminated/truncated."""

    def __init__(self, sim: Simulator, sample_params: ParamSampler, seed: int):
        super().__init__(device=sim.device, batch_size=torch.Size([sim.num_envs]))
        self.sim, self.sample_params = sim, sample_params
        n, obs_dim, act_dim = sim.num_envs, sim.task.obs_dim, sim.task.action_dim
        self.observation_spec = Composite(
            observation=Unbounded((n, obs_dim), dtype=torch.float32, device=self.device), shape=(n,))
        self.action_spec = Bounded(-1.0, 1.0, (n, act_dim), dtype=torch.float32, device=self.device)
        self.reward_spec = Unbounded((n, 1), dtype=torch.float32, device=self.device)
        self.done_spec = Composite(
            {k: Categorical(2, (n, 1), dtype=torch.bool, device=self.device) for k in ("done", "terminated", "truncated")},
            shape=(n,))
        self._obs = torch.zeros(n, obs_dim, dtype=torch.float32, device=self.device)
        self._set_seed(seed)

    def _set_seed(self, seed: int | None) -> None:
        self.generator = torch.Generator().manual_seed(0 if seed is None else int(seed))

    def _reset(self, tensordict: TensorDictBase | None, **kwargs) -> TensorDictBase:
        n = self.sim.num_envs
        mask = None if tensordict is None else tensordict.get("_reset", None)
        ids = torch.arange(n) if mask is None else mask.reshape(n).nonzero().squeeze(-1).cpu()
        if len(ids):
            params = self.sample_params(len(ids), self.generator)
            seed = int(torch.randint(2**31 - 1, (1,), generator=self.generator))
            self._obs[ids.to(self.device)] = self.sim.reset(params, ids, seed=seed).to(self.device, torch.float32)
        false = torch.zeros(n, 1, dtype=torch.bool, device=self.device)
        return TensorDict({"observation": self._obs.clone(), "done": false, "terminated": false.clone(),
                           "truncated": false.clone()}, batch_size=self.batch_size, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        result = self.sim.step(tensordict["action"])
        self._obs = result.obs.to(torch.float32)
        terminated = (result.terminated | result.diverged)[:, None]
        truncated = result.truncated[:, None] & ~terminated
        return TensorDict({"observation": self._obs.clone(), "reward": result.reward.to(torch.float32)[:, None],
                           "done": terminated | truncated, "terminated": terminated, "truncated": truncated},
                          batch_size=self.batch_size, device=self.device)

"""A torchrl EnvBase over any Simulator: N slots, each drawing new physical parameters at its own reset.

Only the Simulator protocol is used (reset with per-slot parameters, step), so the same environment
runs on the native CPU backend and on MJX. The parameter source is a callable `(n, generator) ->
float64 [n, D]`: a posterior's or the prior's `sample`, or a fixed parameter vector (`fixed_params`).

A slot whose simulation diverged is reported as terminated: its observations are frozen and its
rewards zero, so bootstrapping from it would teach the critic a fiction; it restarts at the next reset.

What a slot gets at a reset comes from `ResetDraws`: after every control step, parameters and an initial
state for every slot, used by the slots that reset then. Drawing for all slots whether or not they reset
costs a little, and buys one random stream that the step-by-step environment and the compiled collection
(rl/compiled_collection.py: a whole batch's draws up front) consume alike: same seed, same trajectories.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data.tensor_specs import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from ..sim.base import Simulator
from ..tasks.base import Task

ParamSampler = Callable[[int, torch.Generator], torch.Tensor]


def distribution_sampler(distribution) -> ParamSampler:
    """Draws from any project distribution (prior, posterior): ParameterDistribution.sample takes the generator."""
    return lambda n, generator: distribution.sample((n,), generator=generator).double()


def fixed_params(values: np.ndarray | torch.Tensor) -> ParamSampler:
    """Every slot gets the same parameters (nominal or surrogate-real values)."""
    row = torch.as_tensor(np.asarray(values, dtype=np.float64))[None]
    return lambda n, generator: row.expand(n, -1).clone()


class ResetDraws:
    """Per control step, what each of `num_envs` slots would reset to: parameters [N, D] (float64) and the
    task's initial state fields [N, ...]. Drawn `chunk` steps at a time (one sampler call, one state draw) so
    that a large batch costs few calls; the sequence does not depend on how many steps a caller takes at once."""

    def __init__(self, task: Task, num_envs: int, sample_params: ParamSampler, seed: int, chunk: int = 1):
        self.task, self.num_envs, self.sample_params, self.chunk = task, num_envs, sample_params, max(1, chunk)
        self.generator = torch.Generator().manual_seed(seed)
        self._params = torch.empty(0, num_envs, task.spec.dim, dtype=torch.float64)
        self._states: dict[str, np.ndarray] = {}

    def take(self, steps: int) -> tuple[torch.Tensor, dict[str, np.ndarray]]:
        """The next `steps` steps' draws: params [steps, N, D], state fields [steps, N, ...]."""
        while len(self._params) < steps:
            self._refill()
        params, self._params = self._params[:steps], self._params[steps:]
        states = {k: v[:steps] for k, v in self._states.items()}
        self._states = {k: v[steps:] for k, v in self._states.items()}
        return params, states

    def _refill(self) -> None:
        n, rows = self.num_envs, self.chunk * self.num_envs
        params = torch.as_tensor(self.task.spec.check_values(self.sample_params(rows, self.generator).numpy()))
        seed = int(torch.randint(2**31 - 1, (1,), generator=self.generator))
        states = self.task.reset_state(np.random.default_rng(seed), rows)
        self._params = torch.cat([self._params, params.reshape(self.chunk, n, -1)])
        self._states = {k: np.concatenate([self._states[k], v.reshape((self.chunk, n) + v.shape[1:])])
                        if k in self._states else v.reshape((self.chunk, n) + v.shape[1:]) for k, v in states.items()}


class SimulatorEnv(EnvBase):
    """Batched environment of `sim.num_envs` slots; keys: observation, action, reward, done/terminated/truncated."""

    def __init__(self, sim: Simulator, sample_params: ParamSampler, seed: int, draw_steps: int = 1):
        """draw_steps: ResetDraws' chunk (PPO: its rollout_steps, a batch's worth of draws per sampler call)."""
        super().__init__(device=sim.device, batch_size=torch.Size([sim.num_envs]))
        self.sim, self.sample_params, self.draw_steps = sim, sample_params, draw_steps
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
        self.draws = ResetDraws(self.sim.task, self.sim.num_envs, self.sample_params, 0 if seed is None else int(seed),
                                self.draw_steps)
        self.pending = None  # this step's draws: taken at the first reset and after every step

    def _reset(self, tensordict: TensorDictBase | None, **kwargs) -> TensorDictBase:
        n = self.sim.num_envs
        mask = None if tensordict is None else tensordict.get("_reset", None)
        ids = torch.arange(n) if mask is None else mask.reshape(n).nonzero().squeeze(-1).cpu()
        if self.pending is None:
            self.pending = self.draws.take(1)
        if len(ids):
            params, states = self.pending
            state = {k: v[0, ids.numpy()] for k, v in states.items()}
            self._obs[ids.to(self.device)] = self.sim.reset(params[0, ids], ids, state=state).to(self.device, torch.float32)
        false = torch.zeros(n, 1, dtype=torch.bool, device=self.device)
        return TensorDict({"observation": self._obs.clone(), "done": false, "terminated": false.clone(),
                           "truncated": false.clone()}, batch_size=self.batch_size, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        result = self.sim.step(tensordict["action"])
        self.pending = self.draws.take(1)
        self._obs = result.obs.to(torch.float32)
        terminated = (result.terminated | result.diverged)[:, None]
        truncated = result.truncated[:, None] & ~terminated
        return TensorDict({"observation": self._obs.clone(), "reward": result.reward.to(torch.float32)[:, None],
                           "done": terminated | truncated, "terminated": terminated, "truncated": truncated},
                          batch_size=self.batch_size, device=self.device)

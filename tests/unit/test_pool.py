"""SimulatorPool: chunked rollouts, and one simulator size per run where each size is a compilation."""

from __future__ import annotations

import numpy as np
import torch

from bayessim_exp import registry
from bayessim_exp.sim.native import NativeConfig, NativeSimulator
from bayessim_exp.sim.pool import SimulatorPool

CONFIG = NativeConfig(nthread=1, max_abs_qvel=1.0e4)


class Zeros:
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.zeros(obs.shape[0], 1)


class CompilingNative(NativeSimulator):
    """Native MuJoCo that claims, as MJX does, that every batch size is a compilation."""

    compiles_per_size = True


def _rollout(make, task, params, state):
    pool = SimulatorPool(make, task, chunk=4)
    return pool, pool.rollout(params, Zeros(), horizon=15, seed=3, state=state)


def test_the_last_chunk_runs_padded_in_the_chunk_sized_simulator(compose):
    task = registry.build("task", compose(["task=Pendulum"]).task)
    params = np.random.default_rng(0).uniform(task.spec.low, task.spec.high, (10, task.spec.dim))
    state = {"qpos": np.linspace(-1, 1, 10)[:, None], "qvel": np.linspace(0.5, -0.5, 10)[:, None]}
    padded_pool, padded = _rollout(lambda t, n: CompilingNative(t, n, CONFIG), task, params, state)
    exact_pool, exact = _rollout(lambda t, n: NativeSimulator(t, n, CONFIG), task, params, state)
    assert sorted(padded_pool._sims) == [4] and sorted(exact_pool._sims) == [2, 4]
    assert padded.num == 10
    for field in ("states", "actions", "rewards", "valid", "diverged"):
        torch.testing.assert_close(getattr(padded, field), getattr(exact, field))

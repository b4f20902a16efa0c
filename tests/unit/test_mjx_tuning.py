"""A task's MJX tuning (fewer solver and line-search iterations, docs/tasks.md) keeps its trajectories
close to the stock model's over a short horizon: both models on the native backend (CPU), the same
parameters, initial states and actions. The contact caps are MJX-only numerics MuJoCo ignores."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bayessim_exp import api, registry
from bayessim_exp.sim.native import NativeConfig, NativeSimulator

HORIZON = 10  # control steps; Ant tumbles under the fixed actions and parts from the stock model by step 20
TOLERANCE = 2e-2  # max |Δobs| over the horizon; measured: Ant 2.9e-3, ShadowHand 3.3e-4, ShadowHand_more 1.5e-2,
# Anymal 3.6e-5, FrankaCabinet 0, Humanoid (condim 1 -> 3) 0 (observations of order 1)
TUNED = [n for n in registry.names("task") if api.compose([f"task={n}"]).task.get("mjx_tuning")]


class Replay:
    def __init__(self, actions: np.ndarray):
        self.actions = torch.as_tensor(actions, dtype=torch.float32)

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[t].expand(obs.shape[0], -1)


def test_some_tasks_are_tuned():
    assert {"Ant", "ShadowHand", "Anymal"} <= set(TUNED)


@pytest.mark.parametrize("name", TUNED)
def test_tuned_model_stays_close_to_stock(name):
    cfg = api.compose([f"task={name}"]).task
    stock, tuned = registry.build("task", cfg), registry.build("task", cfg)
    tuned.__dict__["model"] = tuned.mjx_model  # the native backend simulates `model`
    params = np.random.default_rng(0).uniform(stock.spec.low, stock.spec.high, (4, stock.spec.dim))
    t, k = np.arange(HORIZON)[:, None], np.arange(stock.action_dim)[None]
    actions = Replay(0.8 * np.sin(0.7 * t + 1.3 * k))

    def run(task):
        return NativeSimulator(task, 4, NativeConfig(nthread=1, max_abs_qvel=1.0e4)).rollout(params, actions, HORIZON,
                                                                                            seed=0)

    a, b = run(stock), run(tuned)
    assert not a.diverged.any() and not b.diverged.any()
    assert (a.states - b.states).abs().max() < TOLERANCE

"""A task's MJX tuning (conf/mjx_tuning: fewer solver and line-search iterations, docs/tasks.md) keeps its trajectories
close to the stock model's over a short horizon: both models on the native backend (CPU), the same
parameters, initial states and actions. The contact caps are MJX-only numerics MuJoCo ignores."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bayessim_exp import api, registry
from bayessim_exp.policies import OpenLoopPolicy
from bayessim_exp.sim.mjx_tuning import tuned_model
from bayessim_exp.sim.native import NativeConfig, NativeSimulator

HORIZON = 10  # control steps; Ant tumbles under the fixed actions and parts from the stock model by step 20
TOLERANCE = 2e-2  # max |Δobs| over the horizon (observations of order 1); measured 2026-11-22: Ant 7.9e-6,
# ShadowHand 2.2e-4, ShadowHand_more 1.5e-2, Anymal 1.2e-5, Cartpole 0, FrankaCabinet 0, Humanoid 0 (the
# last three: the tuning does not act within these steps, so for them this only guards later tunings)
TUNED = [n for n in registry.names("task") if api.compose([f"task={n}", "sim=mjx"]).sim.tuning]


def test_some_tasks_are_tuned():
    assert {"Ant", "ShadowHand", "Anymal"} <= set(TUNED)


@pytest.mark.parametrize("name", TUNED)
def test_tuned_model_stays_close_to_stock(name):
    cfg = api.compose([f"task={name}", "sim=mjx"])
    task = registry.build("task", cfg.task)
    params = np.random.default_rng(0).uniform(task.spec.low, task.spec.high, (4, task.spec.dim))
    t, k = np.arange(HORIZON)[:, None], np.arange(task.action_dim)[None]
    actions = OpenLoopPolicy(torch.as_tensor(0.8 * np.sin(0.7 * t + 1.3 * k), dtype=torch.float32).expand(4, -1, -1))

    def run(model):
        sim = NativeSimulator(task, 4, NativeConfig(nthread=1, max_abs_qvel=1.0e4), model=model)
        return sim.rollout(params, actions, HORIZON, seed=0)

    a, b = run(task.model), run(tuned_model(task, cfg.sim.tuning))
    assert not a.diverged.any() and not b.diverged.any()
    assert (a.states - b.states).abs().max() < TOLERANCE

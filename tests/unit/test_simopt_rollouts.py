"""SimOpt's simulated counterparts of real roll-outs: restarts from real initial states, replayed actions."""

import logging

import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.inference.simopt.rollouts import simulate_like_real
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.sim.pool import SimulatorPool


def setup(compose, name, chunk=4):
    cfg = compose([f"task={name}"])
    task = registry.build("task", cfg.task)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, chunk)
    real = sims.get(3).rollout(np.repeat(task.true_params[None], 3, 0), RandomPolicy(task.action_dim, 0), 20, 5)
    return task, sims, real


@pytest.mark.parametrize("name", ["Pendulum", "Cartpole"])
def test_replay_at_the_true_parameters_reproduces_every_real_trajectory(compose, name):
    task, sims, real = setup(compose, name)
    other = task.spec.low + 0.3 * (task.spec.high - task.spec.low)
    theta = torch.as_tensor(np.stack([other, task.true_params, other]))
    obs = simulate_like_real(sims, theta, real, None, "recorded", seed=1)  # 9 rows in chunks of 4
    assert obs.shape == (3, 3, 21, task.obs_dim)
    torch.testing.assert_close(obs[1], real.states.double(), atol=1e-5, rtol=0)
    assert (obs[0] - real.states.double()).abs().max() > 0.1
    torch.testing.assert_close(obs[0, :, 0], real.states[:, 0].double(), atol=1e-6, rtol=0)  # same starts


def test_closed_loop_starts_from_the_real_states_with_the_given_policy(compose):
    task, sims, real = setup(compose, "Pendulum")
    obs = simulate_like_real(sims, torch.as_tensor(task.true_params[None]), real, RandomPolicy(1, 9), "closed_loop", 1)
    torch.testing.assert_close(obs[0, :, 0], real.states[:, 0].double(), atol=1e-6, rtol=0)
    assert (obs[0] - real.states.double()).abs().max() > 1e-3  # fresh action noise


def test_a_task_that_cannot_restart_from_observations_uses_its_reset_distribution(compose, monkeypatch, caplog):
    task, sims, real = setup(compose, "Pendulum")
    monkeypatch.setattr(task, "state_from_observation", lambda obs: None)
    with caplog.at_level(logging.WARNING):
        obs = simulate_like_real(sims, torch.as_tensor(task.true_params[None]), real, None, "recorded", 1)
    assert "cannot restart from an observed state" in caplog.text
    assert (obs[0, :, 0] - real.states[:, 0].double()).abs().max() > 1e-3


def test_a_short_last_chunk_runs_padded_in_the_chunk_sized_simulator(compose):
    """SimOpt rolls out through the pool's one chunked path: where each size is a compilation (MJX), 9 rows in
    chunks of 4 build one simulator, not a second for the last row."""
    from bayessim_exp.sim.native import NativeConfig, NativeSimulator

    class CompilingNative(NativeSimulator):
        def pads(self, num_rows: int) -> bool:
            return True

    task, _, real = setup(compose, "Pendulum")
    config = NativeConfig(nthread=1, max_abs_qvel=1.0e4)
    sims = SimulatorPool(lambda t, n: CompilingNative(t, n, config), task, 4)
    theta = torch.as_tensor(np.repeat(task.true_params[None], 3, 0))
    obs = simulate_like_real(sims, theta, real, None, "recorded", seed=1)
    assert sorted(sims._sims) == [4]
    torch.testing.assert_close(obs[2], real.states.double(), atol=1e-5, rtol=0)

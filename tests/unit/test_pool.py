"""SimulatorPool: chunked rollouts, and one simulator size per run where each size is a compilation."""

from __future__ import annotations

import numpy as np
import torch

from bayessim_exp import registry
from bayessim_exp.policies import Policy
from bayessim_exp.sim.native import NativeConfig, NativeSimulator
from bayessim_exp.sim.pool import SimulatorPool

CONFIG = NativeConfig(nthread=1, max_abs_qvel=1.0e4)


class Zeros(Policy):
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.zeros(obs.shape[0], 1)


class CompilingNative(NativeSimulator):
    """Native MuJoCo that claims, as MJX does, that every batch size is a compilation."""

    def pads(self, num_rows: int) -> bool:
        return True


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


def test_a_batch_the_simulator_does_not_pad_runs_in_one_of_its_own_size(compose):
    """As sim=mjx's batches below native_below: a model check's few rows after a collect's chunks run alone (on
    native MuJoCo there), never padded into a chunk-sized rollout."""
    from types import SimpleNamespace

    from bayessim_exp.sim.mjx import MjxConfig, MjxSimulator

    class PadsFromThree(NativeSimulator):
        def pads(self, num_rows: int) -> bool:
            return num_rows >= 3

    task = registry.build("task", compose(["task=Pendulum"]).task)
    pool = SimulatorPool(lambda t, n: PadsFromThree(t, n, CONFIG), task, chunk=4)
    params = np.tile(task.spec.nominal, (10, 1))
    assert pool.rollout(params, Zeros(), horizon=5, seed=3).num == 10 and sorted(pool._sims) == [2, 4]
    assert pool.rollout(params[:7], Zeros(), horizon=5, seed=3).num == 7 and sorted(pool._sims) == [2, 4]
    # MJX's rule: pad from native_below on (below it the sim group's factory builds native MuJoCo)
    mjx = SimpleNamespace(cfg=MjxConfig(max_abs_qvel=1.0e4, cache_dir=None, nthread=1, native_below=1024, impl="jax",
                                        tuning={}))
    assert not MjxSimulator.pads(mjx, 200) and MjxSimulator.pads(mjx, 1024)


def test_a_replay_plan_drives_each_simulation_like_its_recorded_trajectory_across_padded_chunks(compose):
    """policy=replay without noise, at the recording's parameters: every one of 10 simulations (chunks of 4, the
    last padded as on MJX) is exactly the recorded trajectory it drew; with noise the actions differ, in range."""
    from bayessim_exp.policies import RandomPolicy, ReplayPolicy, ReplayPolicyConfig

    task = registry.build("task", compose(["task=Pendulum"]).task)
    params = np.array([[1.3, 0.6]] * 3)
    recorded = NativeSimulator(task, 3, CONFIG).rollout(params, RandomPolicy(1, 5), 15, seed=5)
    pool = SimulatorPool(lambda t, n: CompilingNative(t, n, CONFIG), task, chunk=4)
    exact = ReplayPolicy(ReplayPolicyConfig(action_noise=0.0), recorded, task, seed=0)
    which = torch.randint(3, (10,), generator=torch.Generator().manual_seed(0))  # the plan's draw, same seed
    traj = pool.rollout(np.array([[1.3, 0.6]] * 10), exact, horizon=15, seed=1)
    torch.testing.assert_close(traj.actions, recorded.actions[which])
    torch.testing.assert_close(traj.states, recorded.states[which], atol=1e-5, rtol=0)
    noisy = pool.rollout(np.array([[1.3, 0.6]] * 10), ReplayPolicy(ReplayPolicyConfig(action_noise=0.5), recorded, task,
                                                                    seed=0), horizon=15, seed=1)
    assert not torch.allclose(noisy.actions, recorded.actions[which]) and noisy.actions.abs().max() <= 1.0


def test_replay_without_recorded_trajectories_says_what_it_needs(compose):
    import pytest

    from bayessim_exp.errors import ConfigError
    from bayessim_exp.policies import ReplayPolicy, ReplayPolicyConfig

    task = registry.build("task", compose(["task=Pendulum"]).task)
    with pytest.raises(ConfigError, match="policy=replay replays recorded real trajectories.*real=file"):
        SimulatorPool(lambda t, n: NativeSimulator(t, n, CONFIG), task, chunk=4).rollout(
            np.array([[1.3, 0.6]]), ReplayPolicy(ReplayPolicyConfig(0.0), None, task, seed=0), horizon=5, seed=0)


def test_a_surrogate_under_a_replaying_collect_policy_is_driven_at_random_and_then_replayed(compose, tmp_path):
    """The surrogate 'real' system cannot be driven by the replay of its own trajectories: it acts as a robot under
    its own excitation, uniformly at random with the real stage's seed, and the simulations replay that."""
    from bayessim_exp.pipeline import Pipeline
    from bayessim_exp.policies import RandomPolicy, ReplayPolicy

    pipeline = Pipeline(compose(["debug=smoke", "policy=replay"]), tmp_path)
    policy = pipeline.policy(seed=11)
    assert isinstance(policy, ReplayPolicy)
    real = pipeline.real_source.collect(1, policy, horizon=15, seed=11)
    torch.testing.assert_close(real.actions, RandomPolicy(pipeline.task.action_dim, 11).open_loop_actions(1, 15))


def test_real_data_from_a_file_replay_by_default_and_the_command_line_wins(compose):
    assert compose(["real=file", "real.path=x.npz"]).policy.name == "replay"
    assert compose(["real=file", "real.path=x.npz", "policy=random"]).policy.name == "random"
    assert compose([]).policy.name == "random"


def test_frankacabinet_replays_by_default_and_the_command_line_wins(compose):
    # under random actions its summaries say nothing about its parameters (docs/tasks.md)
    assert compose(["task=FrankaCabinet"]).policy.name == "replay"
    assert compose(["task=FrankaCabinet", "policy=random"]).policy.name == "random"

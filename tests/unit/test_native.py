"""Native backend: per-environment parameters change the dynamics; diverging simulations are flagged."""

import mujoco
import numpy as np
import torch

from bayessim_exp import registry
from bayessim_exp.inference.bayessim.method import BayesSim, BayesSimConfig
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.tasks.base import Task, TaskConfig

SPRING = """
<mujoco>
  <option timestep="0.01" integrator="Euler"/>
  <worldbody><body name="bob"><joint name="slide" type="slide" axis="1 0 0" stiffness="10"/>
    <geom type="sphere" size="0.05" mass="0.01"/></body></worldbody>
  <actuator><motor joint="slide" ctrlrange="-1 1"/></actuator>
</mujoco>"""


class Spring(Task):
    name = "Spring"
    obs_names = ("x", "v")

    @property
    def model(self):
        return mujoco.MjModel.from_xml_string(SPRING)

    def reset_state(self, rng, n):
        return {"qpos": np.full((n, 1), 0.1), "qvel": np.zeros((n, 1))}

    def observe(self, d, xp=np):
        return xp.stack([d.qpos[:, 0], d.qvel[:, 0]], -1)

    def reward(self, obs, action, next_obs, xp=np):
        return -obs[:, 0] ** 2


def native(task, n):
    return registry.build("sim", {"name": "native"})(task, n)


def spring_task():
    # explicit Euler on x'' = -k/m x is unstable once dt * sqrt(k/m) is large: k=1e6, m=0.01 blows up
    cfg = TaskConfig(parameters={"k": {"range": [1.0, 1.0e6], "operation": "set", "targets": ["jnt_stiffness[slide]"]}},
                     real_params={"k": 10.0}, control_dt=0.02, episode_length=200)
    return Spring(cfg)


def test_diverging_simulations_are_flagged_and_kept_apart(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the instability to MUJOCO_LOG.TXT in the working dir
    task = spring_task()
    sim = native(task, 4)
    params = np.array([[10.0], [1.0e6], [100.0], [1.0e6]])
    traj = sim.rollout(params, RandomPolicy(1, 0), 100, seed=0)
    assert traj.diverged.tolist() == [False, True, False, True]
    assert traj.valid[~traj.diverged].all()
    assert not traj.valid[traj.diverged, -1].any()  # invalid from the step it broke down
    assert torch.isfinite(traj.states).all()  # held at the last finite state, never NaN


def test_summarize_drops_and_counts_diverged_simulations(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    task = spring_task()
    traj = native(task, 4).rollout(np.array([[10.0], [1.0e6], [100.0], [1.0e6]]), RandomPolicy(1, 0), 50, seed=0)
    inputs = type("Inputs", (), {"summarizer": lambda self, t: t.states[:, -1], "device": torch.device("cpu")})()
    collected = {"theta": torch.tensor([[10.0], [1.0e6], [100.0], [1.0e6]]), "traj": traj.state_dict()}
    ctx = type("Ctx", (), {"output": lambda self, stage: collected})()
    cfg = BayesSimConfig(proposal="prior", finetune=True, max_components=50, parameter_space="box",
                         combination="product", replay_tempering=True, on_guard="fallback",
                         importance_draws=100_000, escape="nearest", escape_rounds=0, integrators=["model"],
                         summary_error="replays", calibrate_on="latest")
    out = BayesSim(cfg, inputs).summarize(ctx)
    assert out["diverged"] == 2
    assert out["theta"].squeeze(1).tolist() == [10.0, 100.0]


def test_parameters_change_the_dynamics_per_environment(pendulum):
    params = np.array([[1.0, 0.5], [2.0, 0.5], [1.0, 1.0]])

    def run(p):
        return native(pendulum, 3).rollout(p, RandomPolicy(1, 0), 30, seed=0)

    traj, swapped = run(params), run(params[[1, 0, 2]])
    # equal seeds give each slot the same initial state and actions in both runs: only parameters differ
    assert not torch.allclose(traj.states[0], swapped.states[0])
    assert not torch.allclose(traj.states[1], swapped.states[1])
    torch.testing.assert_close(traj.states[2], swapped.states[2])  # same parameters, same trajectory


MARKER = """
<mujoco>
  <worldbody><body name="bob" pos="0 0 1"><joint name="slide" type="slide" axis="1 0 0"/>
    <geom type="sphere" size="0.05" mass="1"/><site name="tip" pos="0 0 0.5"/></body></worldbody>
  <actuator><motor joint="slide" ctrlrange="-1 1"/></actuator>
</mujoco>"""


class Marker(Task):
    name = "Marker"
    obs_names = ("tip_z",)
    data_fields = ("qpos", "qvel", "site_xpos")

    @property
    def model(self):
        return mujoco.MjModel.from_xml_string(MARKER)

    def observe(self, d, xp=np):
        return d.site_xpos[:, 0, 2:3]


def test_first_observation_after_reset_reads_derived_fields():
    cfg = TaskConfig(parameters={"m": {"range": [0.5, 2.0], "targets": ["body_mass[bob]"]}}, real_params={"m": 1.0}, control_dt=0.05,
                     episode_length=200)
    sim = native(Marker(cfg), 2)
    obs = sim.reset(np.ones((2, 1)), None, seed=0)
    np.testing.assert_allclose(obs[:, 0], 1.5)  # site_xpos computed at the reset state, not zeros


def test_zero_threads_are_the_cpus_this_process_may_run_on(pendulum):
    """sim.nthread=0 simulates on the process's CPUs (its affinity: a Slurm job's share, a pinned test worker's),
    not on every CPU of the machine as mujoco.batch's own 0 would; a positive count is taken as given (mujoco.batch
    caps either at the number of simulations)."""
    import os

    from bayessim_exp.sim.native import NativeConfig, NativeSimulator

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert NativeSimulator(pendulum, 256, NativeConfig(nthread=0, max_abs_qvel=1e4)).batch.nthread == min(cpus, 256)
    assert NativeSimulator(pendulum, 8, NativeConfig(nthread=3, max_abs_qvel=1e4)).batch.nthread == 3

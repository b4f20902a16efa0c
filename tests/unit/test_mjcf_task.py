"""task=mjcf: a task built from an MJCF and the YAML alone, on the native backend (test_mjcf_mjx.py: MJX).

The shipped two-link arm (conf/task/mjcf.yaml's default) and models written here: its parameters change
the simulated trajectory, recorded observations give back the state they were taken in (so replays
reproduce a recording), the actions drive the named actuators only, the start is the keyframe plus the
declared noise, reward and termination follow the YAML, and each kind of bad input is one clear error."""

from __future__ import annotations

import textwrap

import mujoco
import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.diagnostics.replay import replay
from bayessim_exp.errors import ConfigError
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.tasks.base import ASSETS

ARM = ASSETS / "two_link_arm" / "two_link_arm.xml"
# a ball joint (4 qpos, 3 dofs) under a hinge; the ball is not actuated, the hinge has no ctrlrange
BALL = """
<mujoco>
  <option timestep="0.01"/>
  <worldbody>
    <body name="link">
      <joint name="swivel" type="ball" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 -0.3" size="0.03" mass="1"/>
      <body name="tip" pos="0.3 0 -0.3">
        <joint name="bend" type="hinge" axis="0 1 0" damping="0.05"/>
        <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02" mass="0.3"/>
        <site name="end" pos="0.2 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="bend_motor" joint="bend" ctrlrange="-1 1"/>
    <motor name="free_motor" joint="bend"/>
  </actuator>
  <sensor>
    <framelinvel name="end_vel" objtype="site" objname="end"/>
    <accelerometer name="end_acc" site="end"/>
  </sensor>
</mujoco>
"""


def arm_cfg(**changes) -> dict:
    """conf/task/mjcf.yaml (the two-link arm) with `changes`; the model as a plain file path."""
    return {**registry.option_defaults("task", "mjcf"), "xml": str(ARM), **changes}


def ball_cfg(tmp_path, **changes) -> dict:
    path = tmp_path / "ball.xml"
    path.write_text(BALL)
    parameters = {"bend_damping": {"range": [0.01, 0.2], "nominal": 0.05, "targets": ["dof_damping[bend]"]}}
    return arm_cfg(xml=str(path), qpos=["*"], qvel=["*"], sensors=["end_vel"], actuators=["bend_motor"],
                   keyframe=None, parameters=parameters, **changes)


def build(cfg: dict):
    return registry.build("task", cfg)


def pool(task) -> SimulatorPool:
    return SimulatorPool(registry.build("sim", {"name": "native", "nthread": 1}), task, chunk=64)


def test_the_default_yaml_is_the_shipped_arm_and_its_parameters_change_the_trajectory():
    task = build(registry.option_defaults("task", "mjcf"))  # xml: pkg://bayessim_exp/...
    assert task.model_path == ARM
    assert task.obs_names == ("shoulder_pos", "elbow_pos", "shoulder_vel", "elbow_vel", "tip_pos_0", "tip_pos_1",
                              "tip_pos_2")
    assert task.action_names == ("shoulder_motor", "elbow_motor") and task.action_dim == 2
    assert task.frame_skip == 4 and task.spec.names == ["elbow_damping", "forearm_mass"]
    np.testing.assert_allclose(task.true_params, [0.1, 0.5])  # real_params {}: the MJCF as written
    params = np.array([[0.1, 0.5], [0.5, 0.5], [0.1, 1.0]])
    start = task.reset_state(np.random.default_rng(0), 1)
    state = {k: np.repeat(v, 3, 0) for k, v in start.items()}
    traj = pool(task).get(3).rollout(params, RandomPolicy(2, 0), 30, state=state)
    s = traj.states.numpy()
    assert not traj.diverged.any()
    np.testing.assert_array_equal(s[:, 0], np.repeat(s[:1, 0], 3, 0))  # one start for all
    # the elbow's damping and the forearm's mass, written into the model by the ParamSpec, move the arm
    assert np.abs(s[1] - s[0]).max() > 1e-2 and np.abs(s[2] - s[0]).max() > 1e-2
    # the tip sensor is the forward kinematics of the observed joint angles, at every step
    q1, q2 = s[..., 0], s[..., 1]
    tip_x = 0.3 * np.cos(q1) + 0.25 * np.cos(q1 + q2)
    np.testing.assert_allclose(s[..., 4], tip_x, atol=1e-5)


def test_a_recorded_start_gives_back_its_state_and_a_replay_reproduces_the_recording():
    task = build(arm_cfg(qpos_noise=0.5, qvel_noise=1.0))
    real = pool(task).get(4).rollout(np.repeat([[0.3, 0.8]], 4, 0), RandomPolicy(2, 1), 25, seed=3)
    start = task.state_from_observation(real.states[:, 0].double().numpy())
    assert set(start) == {"qpos", "qvel"} and start["qpos"].shape == (4, 2)
    out = replay(pool(task), torch.tensor([[0.3, 0.8]] * 4), real, torch.arange(4))
    torch.testing.assert_close(out.states, real.states, atol=1e-4, rtol=0)
    # without every joint's velocity the observation does not determine the state
    assert build(arm_cfg(qvel=["elbow"])).state_from_observation(real.states[:, 0, :6].double().numpy()) is None


def test_ball_joints_patterns_and_an_undriven_actuator(tmp_path):
    task = build(ball_cfg(tmp_path))
    assert task.obs_names == ("swivel_pos_0", "swivel_pos_1", "swivel_pos_2", "swivel_pos_3", "bend_pos",
                              "swivel_vel_0", "swivel_vel_1", "swivel_vel_2", "bend_vel", "end_vel_0", "end_vel_1",
                              "end_vel_2")
    # the actions drive bend_motor across its ctrlrange; free_motor, not named, holds ctrl 0
    np.testing.assert_allclose(task.ctrl(np.array([[0.5], [-2.0]])), [[0.5, 0.0], [-1.0, 0.0]])
    start = task.reset_state(np.random.default_rng(0), 3)
    sim = pool(task).get(3)
    obs = sim.reset(np.full((3, 1), 0.05), None, state=start).double().numpy()
    again = task.state_from_observation(obs)
    np.testing.assert_allclose(again["qpos"], start["qpos"], atol=1e-6)
    np.testing.assert_allclose(again["qvel"], start["qvel"], atol=1e-6)
    m, d = task.model, mujoco.MjData(task.model)  # the velocity sensor as MuJoCo computes it
    d.qpos[:], d.qvel[:] = start["qpos"][1], start["qvel"][1]
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(obs[1, 9:], d.sensordata[:3], atol=1e-5)


def test_the_start_is_the_keyframe_or_qpos0_with_the_declared_noise(tmp_path):
    hanging = build(arm_cfg(qpos_noise=0.0, qvel_noise=0.0)).reset_state(np.random.default_rng(0), 2)
    np.testing.assert_allclose(hanging["qpos"], [[1.5708, 0.0]] * 2)
    np.testing.assert_allclose(hanging["qvel"], 0.0)
    noisy = build(arm_cfg(keyframe=None, qpos_noise=0.2, qvel_noise=0.3)).reset_state(np.random.default_rng(0), 500)
    assert 0.15 < np.abs(noisy["qpos"]).max() <= 0.2 and 0.25 < np.abs(noisy["qvel"]).max() <= 0.3
    ball = build(ball_cfg(tmp_path, qpos_noise=0.3)).reset_state(np.random.default_rng(0), 50)
    np.testing.assert_allclose(np.linalg.norm(ball["qpos"][:, :4], axis=1), 1.0)  # unit quaternions
    assert np.abs(ball["qpos"][:, 1:4]).max() > 0.05


def test_reward_and_termination_follow_the_yaml():
    reward = {"targets": {"elbow_pos": 1.0, "tip_pos_2": 0.0}, "weights": {"elbow_pos": 2.0, "tip_pos_2": 0.5},
              "action_cost": 0.1}
    task = build(arm_cfg(reward=reward, termination={"shoulder_vel": [-3, 3]}))
    assert task.has_reward
    obs = np.zeros((2, 7))
    next_obs = np.zeros((2, 7))
    next_obs[:, 1], next_obs[:, 6] = [1.0, 0.0], [0.0, 2.0]
    action = np.array([[1.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(task.reward(obs, action, next_obs), [-0.1, -(2.0 * 1.0 + 0.5 * 4.0)])
    obs[:, 2] = [2.9, -3.1]
    np.testing.assert_array_equal(task.terminated(obs), [False, True])
    plain = build(arm_cfg())
    assert not plain.has_reward and not plain.terminated(obs).any()
    np.testing.assert_array_equal(plain.reward(obs, action, next_obs), [0.0, 0.0])


def test_a_task_without_a_reward_refuses_rl(compose, tmp_path):
    with pytest.raises(ConfigError, match="task=mjcf defines none.*rl=none"):
        Pipeline(compose(["task=mjcf", "rl=ppo", "debug=smoke"]), tmp_path)


def test_a_model_inside_an_installed_package_is_found_without_importing_it(tmp_path, monkeypatch):
    package = tmp_path / "site" / "robot_models"
    (package / "arm").mkdir(parents=True)
    (package / "__init__.py").write_text("raise ImportError('its dependencies are not installed')\n")
    (package / "arm" / "arm.xml").write_text(ARM.read_text())
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    task = build(arm_cfg(xml="pkg://robot_models/arm/arm.xml"))
    assert task.model_path == package / "arm" / "arm.xml" and task.model.nu == 2


BAD = {  # YAML changes -> what the one error says
    "missing file": ({"xml": "no/such/robot.xml"}, r"no such file .*no/such/robot\.xml"),
    "unknown package": ({"xml": "pkg://no_such_package_xyz/robot.xml"}, "no installed package 'no_such_package_xyz'"),
    "file not in the package": ({"xml": "pkg://bayessim_exp/robot.xml"}, "package 'bayessim_exp' .* has no file robot.xml"),
    "package path syntax": ({"xml": "pkg://bayessim_exp"}, r"write pkg://<top-level package>/<path inside it>"),
    "unknown joint": ({"qpos": ["shoulder", "elbw"]}, r"qpos: unknown joint 'elbw' \(did you mean elbow\?\); the joints: shoulder, elbow"),
    "pattern matching nothing": ({"qvel": ["wrist_*"]}, "pattern 'wrist_\\*' matches no joint; the joints: shoulder, elbow"),
    "joint named twice": ({"qpos": ["elbow", "*"]}, "qpos names joint 'elbow' twice"),
    "unknown sensor": ({"sensors": ["tip_ps"]}, r"sensors: unknown sensor 'tip_ps' \(did you mean tip_pos\?\); the sensors: tip_pos"),
    "unknown actuator": ({"actuators": ["elbow"]}, r"unknown actuator 'elbow' \(did you mean elbow_motor"),
    "no actuator": ({"actuators": []}, "name at least one actuator"),
    "nothing observed": ({"qpos": [], "qvel": [], "sensors": []}, "nothing is observed"),
    "unknown keyframe": ({"keyframe": "home"}, "unknown keyframe 'home'.*the keyframes: hanging"),
    "control_dt": ({"control_dt": 0.012}, "control_dt=0.012 is not a whole multiple of the model timestep 0.005"),
    "reward names": ({"reward": {"targets": {"elbow_pos": 0.0}, "weights": {"elbow": 1.0}, "action_cost": 0.0}},
                     "reward.targets and reward.weights must name the same observations"),
    "reward observation": ({"reward": {"targets": {"elbw_pos": 0.0}, "weights": {"elbw_pos": 1.0}, "action_cost": 0.0}},
                           r"reward.targets: unknown observation 'elbw_pos' \(did you mean elbow_pos"),
    "termination observation": ({"termination": {"tip_z": [-1, 1]}}, "termination: unknown observation 'tip_z'"),
    "termination bounds": ({"termination": {"tip_pos_2": [1, -1]}}, r"termination.tip_pos_2 must be \[low, high\]"),
    "termination scalar": ({"termination": {"tip_pos_2": 1.0}}, r"termination.tip_pos_2 must be \[low, high\].*got 1.0"),
    "real_params name": ({"real_params": {"elbow_damp": 0.2}}, r"real_params names unknown parameters \['elbow_damp'\]"),
    "nominal outside the range": ({"parameters": {"m": {"range": [1.0, 2.0], "nominal": 0.5, "targets": ["body_mass[forearm]"]}}},
                                  r"real_params.m=0.5 \(its nominal value.*outside its range"),
    "unknown parameter target": ({"parameters": {"m": {"range": [0.1, 2.0], "nominal": 0.5, "targets": ["body_mass[forarm]"]}}},
                                 "unknown body 'forarm'; closest valid: forearm"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_clear_error(case):
    changes, message = BAD[case]
    with pytest.raises(ConfigError, match=message):
        build(arm_cfg(**changes))


def test_model_errors_are_config_errors(tmp_path):
    ball = ball_cfg(tmp_path)
    with pytest.raises(ConfigError, match=r"sensors: 'end_acc' \(accelerometer\) reads accelerations"):
        build({**ball, "sensors": ["end_vel", "end_acc"]})
    with pytest.raises(ConfigError, match=r"actuators \['free_motor'\] have no ctrlrange"):
        build({**ball, "actuators": ["*"]})
    broken = tmp_path / "broken.xml"
    broken.write_text(textwrap.dedent(BALL).replace("</worldbody>", ""))
    with pytest.raises(ConfigError, match="MuJoCo cannot load .*broken.xml"):
        build({**ball, "xml": str(broken)})


def test_a_csv_log_of_the_driven_actuators_alone_reads_back(compose, tmp_path):
    """A log holds the observations and the commands of the actuators the actions drive (here the elbow alone,
    in N m): it reads back as the simulated trajectories, the commands normalised by that actuator's ctrlrange."""
    import csv

    task = build(arm_cfg(actuators=["elbow_motor"]))
    assert task.action_names == ("elbow_motor",) and list(task.actuators) == [1]
    rng = np.random.default_rng(0)
    traj = pool(task).get(2).rollout(np.repeat([[0.2, 0.7]], 2, 0), RandomPolicy(1, 2), 25,
                                     state=task.reset_state(rng, 2))
    states, actions = traj.states.double().numpy(), traj.actions.double().numpy()
    for e in range(2):
        torque = 1.5 * np.concatenate([actions[e, :, 0], actions[e, -1:, 0]])  # ctrlrange [-1.5, 1.5] N m
        with (tmp_path / f"run{e}.csv").open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["time", *task.obs_names, "elbow_motor"])
            out.writerows([[t * 0.02, *states[e, t], torque[t]] for t in range(26)])
    cfg = compose(["task=mjcf", "real=csv", f"real.path={tmp_path}"]).real
    real = registry.build("real", cfg, task=task)
    real.check(25)
    got = real.collect(1, None, 25, 0)
    torch.testing.assert_close(got.states, traj.states, atol=1e-5, rtol=0)
    torch.testing.assert_close(got.actions, traj.actions, atol=1e-5, rtol=0)

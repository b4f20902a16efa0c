"""`python -m bayessim_exp real=lerobot|csv real.path=... debug=smoke` runs end to end on Pendulum, from a log made by
our own simulator at known parameters: the LeRobot dataset in a robot's units, mapped on the command line."""

import math

import numpy as np
import pytest
import torch

from bayessim_exp import api, registry
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.policies import OpenLoopPolicy
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.testing.robot_logs import write_csv, write_lerobot

pytestmark = pytest.mark.slow


def _motions(episodes=3, steps=30):
    task = registry.build("task", api.compose(["sim=native"]).task)
    rng = np.random.default_rng(1)
    actions = torch.as_tensor(rng.uniform(-1, 1, (episodes, steps, 1)), dtype=torch.float32)
    pool = SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=16)
    traj = pool.rollout(np.tile([1.3, 0.6], (episodes, 1)), OpenLoopPolicy(actions), steps, seed=0,
                        state=task.reset_state(rng, episodes))
    theta = torch.atan2(traj.states[..., 1], traj.states[..., 0]).numpy()
    torque = 2 * np.concatenate([traj.actions.numpy(), traj.actions.numpy()[:, -1:]], 1)
    return theta, traj.states[..., 2].numpy(), torque


@pytest.mark.parametrize("option", ["lerobot", "csv"])
def test_smoke_run_from_a_robot_log(compose, tmp_path, option):
    theta, speed, torque = _motions()
    if option == "lerobot":  # degrees from hanging down, a v3.0 dataset
        episodes = [{"observation.state": np.stack([np.degrees(t - np.pi), np.degrees(v)], -1), "action": u}
                    for t, v, u in zip(theta, speed, torque)]
        path = write_lerobot(tmp_path / "log", episodes, {"observation.state": ["shoulder.pos", "shoulder.vel"],
                                                          "action": ["shoulder.effort"]})
        angle = f"from:observation.state.shoulder.pos,unit:deg,offset:{math.pi}"
        mapping = [f"real.observations={{cos_theta:{{{angle},transform:cos}},sin_theta:{{{angle},transform:sin}},"
                   "theta_dot:{from:observation.state.shoulder.vel,unit:deg}}", "real.actions={torque:action}"]
    else:
        for e, (t, v, u) in enumerate(zip(theta, speed, torque)):
            write_csv(tmp_path / "log" / f"run{e}.csv", {"time": np.arange(len(t)) * 0.05, "cos_theta": np.cos(t),
                                                       "sin_theta": np.sin(t), "theta_dot": v, "torque": u[:, 0]})
        path, mapping = tmp_path / "log", []
    results = Pipeline(compose([f"real={option}", f"real.path={path}", *mapping, "debug=smoke"]), tmp_path / "run").run()
    assert results["policy"] == "replay"
    assert [r["round"] for r in results["rounds"]] == [1, 2]
    last = results["rounds"][-1]
    assert last["real_trajectories"] == 3
    assert all(math.isfinite(v) and last["posterior_std"][k] > 0 for k, v in last["posterior_mean"].items())
    assert (tmp_path / "run" / "real_data.sha256").is_file()

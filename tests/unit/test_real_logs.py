"""real=lerobot and real=csv: a Pendulum log made by our own simulator at known parameters, written as LeRobot v2
and v3 datasets and as CSV, reads back as the npz reader's trajectories, in the task's units or in a robot's
(degrees from hanging down, mN m), at the control rate or resampled from a faster log; malformed logs are refused
when the run is built, with one error each that says where and what to do."""

import math
import sys

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from bayessim_exp import api, registry
from bayessim_exp.errors import ConfigError, DataError
from bayessim_exp.policies import OpenLoopPolicy
from bayessim_exp.real import load_trajectories, save_trajectories
from bayessim_exp.recorded import resample
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.testing.robot_logs import NAMES, pendulum_frames, write_csv, write_lerobot

pytestmark = pytest.mark.xdist_group("test_real_logs")  # one worker: `recorded` is made once
STEPS, FAST = 30, 5  # control steps; the fast log's frames per control step (100 Hz for 20 Hz)


def _rollout(overrides, actions, state):
    task = registry.build("task", api.compose(["sim=native", *overrides]).task)
    pool = SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=16)
    traj = pool.rollout(np.tile([1.3, 0.6], (len(actions), 1)), OpenLoopPolicy(actions), actions.shape[1], seed=0,
                        state=state)
    return task, traj


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Three episodes at 20 Hz (the task's control rate), the npz reader's trajectories of them, and the same
    motions logged at 100 Hz (the commands held for five frames)."""
    rng = np.random.default_rng(0)
    actions = torch.as_tensor(rng.uniform(-1, 1, (3, STEPS, 1)), dtype=torch.float32)
    task, _ = _rollout([], actions, None)
    state = task.reset_state(rng, 3)
    task, traj = _rollout([], actions, state)
    path = tmp_path_factory.mktemp("npz") / "robot.npz"
    save_trajectories(path, traj)
    with np.load(path) as data:
        reference = load_trajectories(dict(data), task, STEPS, str(path))
    _, fast = _rollout(["task.control_dt=0.01"], actions.repeat_interleave(FAST, 1), state)
    return task, reference, fast


def _read(compose, task, option, path, **settings):
    cfg = compose([f"real={option}", f"real.path={path}"]).real
    for key, value in settings.items():
        cfg[key] = OmegaConf.create(value) if isinstance(value, (dict, list)) else value
    real = registry.build("real", cfg, task=task)
    real.check(STEPS)
    return real


def _assert_same(real, reference, atol=1e-5):
    got = real.collect(1, None, STEPS, 0)
    assert got.dt == reference.dt and got.states.shape == reference.states.shape
    torch.testing.assert_close(got.states, reference.states, atol=atol, rtol=0)
    torch.testing.assert_close(got.actions, reference.actions, atol=1e-5, rtol=0)


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_a_lerobot_dataset_in_the_tasks_names_reads_as_the_npz(compose, recorded, tmp_path, version):
    task, reference, _ = recorded
    root = write_lerobot(tmp_path / "ds", pendulum_frames(reference.states.numpy(), reference.actions.numpy()),
                         NAMES, version=version)
    _assert_same(_read(compose, task, "lerobot", root), reference)
    second = _read(compose, task, "lerobot", root, episodes=[2, 0])
    torch.testing.assert_close(second.collect(1, None, STEPS, 0).states, reference.states[[2, 0]], atol=1e-5, rtol=0)


def test_a_robots_units_and_angle_convention_are_mapped(compose, recorded, tmp_path):
    """The joint angle logged in degrees from hanging down (wrapped to [-180, 180)), its speed in deg/s, the
    torque in mN m: mapped by unit, offset and cos/sin, the same trajectories."""
    task, reference, _ = recorded
    states, actions = reference.states.numpy().astype(float), reference.actions.numpy().astype(float)
    theta = np.arctan2(states[..., 1], states[..., 0])
    hanging = (np.degrees(theta - np.pi) + 180) % 360 - 180
    episodes = [{"observation.state": np.stack([h, np.degrees(s[:, 2])], -1),
                 "action": 2000 * np.concatenate([a, a[-1:]])} for h, s, a in zip(hanging, states, actions)]
    root = write_lerobot(tmp_path / "ds", episodes, {"observation.state": ["shoulder.pos", "shoulder.vel"],
                                                     "action": ["shoulder.effort"]})
    angle = {"from": "observation.state.shoulder.pos", "unit": "deg", "offset": math.pi}
    real = _read(compose, task, "lerobot", root, observations={
        "cos_theta": {**angle, "transform": "cos"}, "sin_theta": {**angle, "transform": "sin"},
        "theta_dot": {"from": "observation.state[1]", "unit": "deg"}}, actions={"torque": {"from": "action", "scale": 1e-3}})
    _assert_same(real, reference, atol=2e-5)


def test_a_faster_log_is_resampled_to_the_control_rate(compose, recorded, tmp_path):
    """100 Hz frames of the same motions: states every fifth frame, the held commands averaged; the speed derived
    from the logged angle alone (transform: angle_rate, across its wrap at pi) agrees to the finite difference's error."""
    task, reference, fast = recorded
    root = write_lerobot(tmp_path / "ds", pendulum_frames(fast.states.numpy(), fast.actions.numpy()), NAMES,
                         fps=100, version="v2.1")
    _assert_same(_read(compose, task, "lerobot", root), reference)
    theta = torch.atan2(fast.states[..., 1], fast.states[..., 0]).numpy()
    for e in range(3):
        write_csv(tmp_path / "csv" / f"run{e}.csv", {"time": np.arange(STEPS * FAST + 1) / 100, "angle": theta[e],
                                                   "torque": 2 * np.append(fast.actions[e, :, 0], 0)})
    spec = {"from": "angle"}
    real = _read(compose, task, "csv", tmp_path / "csv", observations={
        "cos_theta": {**spec, "transform": "cos"}, "sin_theta": {**spec, "transform": "sin"},
        "theta_dot": {**spec, "transform": "angle_rate"}})
    got = real.collect(1, None, STEPS, 0)
    torch.testing.assert_close(got.states[..., :2], reference.states[..., :2], atol=1e-5, rtol=0)
    # central differences at 100 Hz miss the kinks the torque's steps put into the speed: 0.14 rad/s at most here
    assert (got.states[..., 2] - reference.states[..., 2]).abs().max() < 0.3
    assert (got.states[..., 2] - reference.states[..., 2]).abs().mean() < 0.06


@pytest.mark.parametrize("layout", ["file_per_episode", "episode_column"])
def test_a_csv_log_reads_as_the_npz(compose, recorded, tmp_path, layout):
    task, reference, _ = recorded
    frames = pendulum_frames(reference.states.numpy(), reference.actions.numpy())
    tables = [{"t_ms": 50.0 * np.arange(STEPS + 1), **{n: f["observation.state"][:, k] for k, n in
              enumerate(NAMES["observation.state"])}, "torque": f["action"][:, 0]} for f in frames]
    if layout == "file_per_episode":
        for e, table in enumerate(tables):
            write_csv(tmp_path / "log" / f"run{e}.csv", table)
        real = _read(compose, task, "csv", tmp_path / "log", time_column="t_ms", time_scale=1e-3)
    else:
        joined = {k: np.concatenate([t[k] for t in tables]) for k in tables[0]}
        joined["episode"] = np.repeat([7, 8, 9], STEPS + 1)
        real = _read(compose, task, "csv", write_csv(tmp_path / "log.csv", joined), time_column="t_ms",
                     time_scale=1e-3, episode_column="episode")
        assert list(real.episodes) == ["7", "8", "9"]
    _assert_same(real, reference)


def test_hold_average_keeps_the_impulse_of_commands_at_any_rate_ratio():
    """30 Hz commands over 20 Hz steps: each step's mean is the time-weighted mean of the commands it spans."""
    times, commands = np.arange(7) / 30, np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 0.0])
    grid = resample.control_times(times, 0.05, "log")
    np.testing.assert_allclose(grid, [0, 0.05, 0.1, 0.15, 0.2])
    np.testing.assert_allclose(resample.hold_average(times, commands, grid), [1 + 1 / 3, 2 + 2 / 3, 4 + 1 / 3, 5 + 2 / 3])
    np.testing.assert_allclose(resample.interpolate(times, 3 * times, grid), 3 * grid)
    jittered = np.arange(11) * 0.05 + np.tile([0, 0.002], 6)[:11]  # a robot's clock: steps of 0.048 s to 0.052 s
    np.testing.assert_allclose(resample.control_times(jittered, 0.05, "log"), np.arange(11) * 0.05)
    with pytest.raises(DataError, match="time jumps by 0.1 s at row 4"):
        resample.control_times(np.delete(np.arange(11) * 0.05, 4), 0.05, "log")


def _pendulum_lerobot(tmp_path, recorded, **kwargs):
    _, reference, _ = recorded
    frames = pendulum_frames(reference.states.numpy(), reference.actions.numpy())
    return write_lerobot(tmp_path / "ds", frames, kwargs.pop("names", NAMES), **kwargs), frames


@pytest.mark.parametrize("case, error, message", [
    ("missing_feature", ConfigError, r"real.observations.theta_dot: the log names no element 'theta_dot'.*"
                                     r"closest: observation.state.theta_vel.*holds observation.state.cos_theta"),
    ("typo_in_mapping", ConfigError, r"'observation.state.theta_dott' is not in the log \(closest: "
                                     r"observation.state.theta_dot\)"),
    ("wrong_fps", DataError, r"episode 0: meta/info.json gives fps=30 but the time stamps step by 0.05 s"),
    ("slower_than_control", DataError, r"episode 0: recorded every 0.1 s \(10 Hz\), slower than the task's control "
                                       r"step 0.05 s"),
    ("gap", DataError, r"episode 1: time jumps by 0.15 s at row 10 .*frames are missing"),
    ("nan", DataError, r"episode 1: observation.state.theta_dot \(the task's theta_dot\) is nan at row 7"),
    ("no_info", DataError, r"no meta/info.json; a LeRobot dataset directory holds meta/info.json and data/"),
    ("torque_in_mNm", DataError, r"action.torque \(actuator torque\) gives .* outside \[-2, 2\] .*check its unit"),
    ("short", DataError, r"episodes 0 \(9 steps\) are shorter than collect.horizon=30 .*real.episodes=\[1,2\]"),
    ("unknown_episode", DataError, r"real.episodes names \[5\], which the log does not hold; it holds 0, 1, 2"),
])
def test_a_malformed_lerobot_dataset_gets_one_clear_error(compose, recorded, tmp_path, case, error, message):
    task = recorded[0]
    settings = {}
    if case == "missing_feature":
        root, _ = _pendulum_lerobot(tmp_path, recorded, names={**NAMES, "observation.state": ["cos_theta", "sin_theta",
                                                                                               "theta_vel"]})
    elif case == "typo_in_mapping":
        root, _ = _pendulum_lerobot(tmp_path, recorded)
        settings["observations"] = {"theta_dot": "observation.state.theta_dott"}
    elif case == "wrong_fps":
        root, _ = _pendulum_lerobot(tmp_path, recorded, fps=30, times=lambda e, n: np.arange(n) / 20)
    elif case == "slower_than_control":
        root, _ = _pendulum_lerobot(tmp_path, recorded, fps=10)
    elif case == "gap":
        root, _ = _pendulum_lerobot(tmp_path, recorded, times=lambda e, n: np.arange(n) / 20 + (np.arange(n) >= 10) * 0.1
                                    * (e == 1))
    elif case == "nan":
        _, reference, _ = recorded
        frames = pendulum_frames(reference.states.numpy(), reference.actions.numpy())
        frames[1]["observation.state"][7, 2] = np.nan
        root = write_lerobot(tmp_path / "ds", frames, NAMES)
    elif case == "no_info":
        root, _ = _pendulum_lerobot(tmp_path, recorded)
        (root / "meta" / "info.json").unlink()
    elif case == "torque_in_mNm":
        _, reference, _ = recorded
        root = write_lerobot(tmp_path / "ds", pendulum_frames(reference.states.numpy(), 1000 * reference.actions.numpy()),
                             NAMES)
    elif case == "short":
        _, reference, _ = recorded
        frames = pendulum_frames(reference.states.numpy(), reference.actions.numpy())
        frames[0] = {k: v[:10] for k, v in frames[0].items()}
        root = write_lerobot(tmp_path / "ds", frames, NAMES, version="v2.1")
    else:
        root, _ = _pendulum_lerobot(tmp_path, recorded)
        settings["episodes"] = [5]
    with pytest.raises(error, match=message) as raised:
        _read(compose, task, "lerobot", root, **settings)
    assert raised.type is error


def test_a_changed_data_file_changes_the_fingerprint(compose, recorded, tmp_path):
    task, reference, _ = recorded
    root, frames = _pendulum_lerobot(tmp_path, recorded, version="v2.1")
    before = _read(compose, task, "lerobot", root).fingerprint
    assert _read(compose, task, "lerobot", root).fingerprint == before
    frames[2]["action"][3] *= 0.5
    write_lerobot(root, frames, NAMES, version="v2.1")
    assert _read(compose, task, "lerobot", root).fingerprint != before


def test_without_pyarrow_real_lerobot_names_the_extra(compose, recorded, tmp_path, monkeypatch):
    root, _ = _pendulum_lerobot(tmp_path, recorded)
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    with pytest.raises(ConfigError, match=r"pyarrow, which is not installed: pip install 'bayessim_exp\[robot\]'"):
        _read(compose, recorded[0], "lerobot", root)


def test_a_malformed_csv_gets_one_clear_error(compose, recorded, tmp_path):
    task = recorded[0]
    table = {"time": np.arange(STEPS + 1) / 20, "cos_theta": np.ones(STEPS + 1), "sin_theta": np.zeros(STEPS + 1),
             "theta_dot": np.zeros(STEPS + 1), "torque": np.zeros(STEPS + 1)}
    path = write_csv(tmp_path / "run.csv", table)
    with pytest.raises(DataError, match=r"run.csv: no column 'timestamp' for real.time_column \(closest: time\)"):
        _read(compose, task, "csv", path, time_column="timestamp")
    lines = [line.split(",") for line in path.read_text().splitlines()]
    lines[5][3] = "fast"
    path.write_text("\n".join(",".join(cells) for cells in lines) + "\n")
    with pytest.raises(DataError, match=r"run.csv: line 6, column theta_dot: 'fast' is not a number"):
        _read(compose, task, "csv", path)

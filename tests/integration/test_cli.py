"""The real CLI in a subprocess: errors before any simulation, and a --multirun sweep."""

import json
import os
import re
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow


def cli(*args, cwd):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "bayessim_exp", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


@pytest.mark.parametrize("args, expected", [
    (["task=Nope"], ["Nope", "Available options in 'task'", "Pendulum"]),
    (["model.components=abc"], ["model.components='abc'", "expected int"]),
    (["+model.componentz=3"], ["model.componentz", "did you mean components", "allowed keys"]),
    (["summarizer.steps=80"], ["steps=80 exceeds the trajectory horizon 50"]),
    (["collect.horizon=ten"], ["collect.horizon", "'ten'"]),
])
def test_bad_config_fails_fast_with_the_allowed_values(tmp_path, args, expected):
    proc = cli(*args, f"hydra.run.dir={tmp_path}/run", cwd=tmp_path)
    assert proc.returncode != 0
    for text in expected:
        assert text in proc.stderr, proc.stderr
    assert not list(tmp_path.glob("run/round_*"))  # refused before anything was simulated


def test_help_says_what_the_program_does_and_lists_the_config_groups(tmp_path):
    proc = cli("--help", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    for text in ("BayesSim on MuJoCo", "python -m bayessim_exp debug=smoke", "make sweep SWEEP=models",
                 "python -m bayessim_exp.report", "README.md", "docs/"):
        assert text in proc.stdout, proc.stdout
    assert re.search(r"^model: .*\blinear\b.*\bmdnn\b", proc.stdout, re.M)  # Hydra's $APP_CONFIG_GROUPS
    assert re.search(r"^task: .*\bPendulum\b", proc.stdout, re.M)
    assert not list(tmp_path.iterdir())  # nothing ran


def test_multirun_goes_on_past_a_failing_job_and_names_it(tmp_path):
    proc = cli("--multirun", "debug=smoke", "model.components=0,3", "seed=1", "rounds=1",
                  f"hydra.sweep.dir={tmp_path}/sweep", cwd=tmp_path)
    sweep = tmp_path / "sweep"
    runs = sorted(p.name for p in sweep.iterdir() if p.is_dir() and p.name[0].isdigit())
    assert runs == ["0_Pendulum_bayessim_mdnn_start_random_seed1", "1_Pendulum_bayessim_mdnn_start_random_seed1"]
    failed, finished = sweep / runs[0], sweep / runs[1]
    assert "components must be an integer >= 1, got 0" in (failed / "error.txt").read_text()
    assert not (failed / "results.json").exists()
    results = json.loads((finished / "results.json").read_text())
    assert results["seed"] == 1 and len(results["rounds"]) == 1
    assert proc.returncode == 1
    assert "1 job(s) failed" in proc.stderr and str(failed) in proc.stderr


PLUGIN = '''
import atexit
import dataclasses
import pathlib
from bayessim_exp.registry import register

atexit.register(lambda: pathlib.Path("exit_handler_ran").write_text("yes"))


@dataclasses.dataclass
class FinalStateConfig:
    pass


@register("summarizer", "final_state", FinalStateConfig)
class FinalState:
    def __init__(self, cfg):
        pass

    def check(self, horizon):
        pass

    def output_dim(self, state_dim, action_dim, horizon):
        return state_dim

    def __call__(self, traj):
        return traj.states[:, -1]
'''


def test_a_component_registered_outside_the_package(tmp_path):
    (tmp_path / "mylab").mkdir()
    (tmp_path / "mylab" / "__init__.py").write_text("")
    (tmp_path / "mylab" / "final.py").write_text(PLUGIN)
    (tmp_path / "conf" / "summarizer").mkdir(parents=True)
    (tmp_path / "conf" / "summarizer" / "final_state.yaml").write_text("# the last state\nname: final_state\n")
    proc = cli("plugins=[mylab.final]", f"hydra.searchpath=[file://{tmp_path}/conf]", "summarizer=final_state",
                  "debug=smoke", "rounds=1", f"hydra.run.dir={tmp_path}/run", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert results["summarizer"] == "final_state" and results["run_name"] == "Pendulum_bayessim_mdnn_final_state_random_seed0"
    # the process leaves before the interpreter's finalization: output, log and exit handlers are complete
    assert "log p(true | real) - log p(true)" in proc.stdout
    assert "round 1: score done" in (tmp_path / "run" / "__main__.log").read_text()
    assert (tmp_path / "exit_handler_ran").read_text() == "yes"

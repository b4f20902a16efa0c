"""`python -m bayessim_exp <group>=<option> debug=smoke` runs end to end for each option that no other test runs
(every option builds under debug=smoke in tests/unit/test_config.py), and every option is run somewhere."""

import math
from pathlib import Path

import pytest

from bayessim_exp import registry
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow

CONF = Path(__file__).resolve().parents[2] / "conf"
GROUPS = (*registry.GROUPS, "experiment")

RUN_HERE = ["prior=loguniform", "prior=gaussian", "policy=fixed", "policy=rl", "policy=replay", "model=linear", "sim=native",
            "experiment=bayessimig_pendulum", "experiment=gpu_pendulum", "experiment=gpu_humanoid"]
# run end to end elsewhere: a whole group, or one option (the defaults run in nearly every test)
RUN_ELSEWHERE = {
    "task": "test_tasks_pipeline.py, with each task's own summarizer and model (the mdnn_projected_* variants)",
    "task=mjcf": "test_own_robot.py, README's commands through the CLI (the shipped arm; a task YAML of one's own, with a LeRobot log)",
    "summarizer": "test_summarizers_pipeline.py",
    "prior=uniform": "the default", "method=bayessim": "the default", "policy=random": "the default",
    "model=mdnn": "the default", "rl=none": "the default", "sim=auto": "the default", "real=surrogate": "the default",
    "method=simopt": "test_simopt_pipeline.py", "method=sysid": "test_sysid_pipeline.py", "policy=rl_randomized": "test_rl_pipeline.py",
    "rl=ppo": "test_rl_pipeline.py", "real=file": "test_pipeline.py, test_real_data.py",
    "real=lerobot": "test_real_logs_pipeline.py", "real=csv": "test_real_logs_pipeline.py",
    "model=mdrff": "test_pipeline.py", "model=flow": "test_pipeline.py",
    "model=mdnn_projected_diagonal": "task=Ant", "model=mdnn_projected_diagonal_ensemble":
        "task=ShadowHand_more", "model=mdnn_projected_diagonal_one_component": "task=Humanoid",
    "model=mdnn_projected_gaussian_ensemble": "task=ShadowHand, task=Cartpole",
}
# built only: MJX compiles a model for about a minute on CPU (README, 'Install and test'), too slow for every CI run
BUILD_ONLY = ["sim=mjx"]


@pytest.mark.parametrize("option", RUN_HERE)
def test_smoke_run_of_an_option_completes(compose, tmp_path, option):
    results = Pipeline(compose([option, "debug=smoke"]), tmp_path).run()
    assert [r["round"] for r in results["rounds"]] == [1, 2]
    last = results["rounds"][-1]
    assert last["diverged"] < last["sim_trajectories"] / 10
    assert all(math.isfinite(v) and last["posterior_std"][k] > 0 for k, v in last["posterior_mean"].items())
    assert last["log_prob_true_posterior"] is not None


def test_every_option_is_run_by_some_test():
    options = {f"{g}={p.stem}" for g in GROUPS for p in (CONF / g).glob("*.yaml")}
    covered = set(RUN_HERE) | set(BUILD_ONLY) | {o for o in options if o in RUN_ELSEWHERE
                                                 or o.split("=")[0] in RUN_ELSEWHERE}
    assert options - covered == set(), "run the new option's smoke here (RUN_HERE) or name the test that runs it"

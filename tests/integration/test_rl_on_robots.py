"""scripts/rl_on_robots.py at smoke budgets: the uniform prior's and the nominal policies are trained once per seed
and scored on every setting's surrogate real system, the posteriors' per (setting, seed), and a rerun keeps what
finished instead of training again."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ["sim=native", "sim.nthread=1", "device=cpu", "logging.progress=false", "debug=smoke"]


def study(tmp_path: Path, *trained_on: str) -> dict:
    done = subprocess.run(
        [sys.executable, "scripts/rl_on_robots.py", "--task", "Cartpole", "--settings", "0", "1", "--seeds", "3",
         "--trained-on", *trained_on, "--rounds", "2", "--episodes", "2", "--overrides", *SMOKE,
         "--rl-overrides", *SMOKE, "--out", str(tmp_path / "study.json"), "--run-dir", str(tmp_path / "runs")],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return {"stdout": done.stdout, **json.loads((tmp_path / "study.json").read_text())}


def test_baselines_train_once_per_seed_and_posteriors_per_pair_and_a_rerun_keeps_them(tmp_path):
    runs = tmp_path / "runs"
    baselines = study(tmp_path, "prior", "nominal")
    assert [(r["setting"], r["seed"]) for r in baselines["runs"]] == [(0, 3), (1, 3)]
    assert baselines["runs"][0]["real"] != baselines["runs"][1]["real"]
    for name in ("prior", "nominal"):
        trained = (runs / f"Cartpole_seed3_{name}" / "round_001" / "train_policy.pt").read_bytes()
        assert (runs / f"Cartpole_setting1_seed3_{name}" / "round_001" / "train_policy.pt").read_bytes() == trained
        assert (runs / f"Cartpole_setting1_seed3_{name}" / "round_001" / "evaluate.pt").is_file()
    assert not (runs / "Cartpole_setting0_seed3").exists()  # no BayesSim for the baselines

    both = study(tmp_path, "posterior_round_1", "posterior", "prior", "nominal")
    assert "prior:" not in both["stdout"] and both["stdout"].count("posterior:") == 2  # only the missing scores
    assert all(set(r) >= {"posterior_round_1", "posterior", "prior", "nominal", "bayessim_seconds"} for r in both["runs"])
    assert [r["prior"] for r in both["runs"]] == [r["prior"] for r in baselines["runs"]]
    assert study(tmp_path, "posterior", "prior")["stdout"] == ""  # everything there: nothing runs

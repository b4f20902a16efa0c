"""rl=ppo inside the pipeline: train_policy and evaluate every round, the next round collecting with the
trained actor (policy=rl_randomized), and a run killed during train_policy resuming from the last
finished stage."""

import json
import math

import pytest

from bayessim_exp.inference.bayessim.method import BayesSim
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.rl.component import PPOComponent
from bayessim_exp.rl.ppo import PPOTrainer

pytestmark = pytest.mark.slow

RL_SMOKE = ["task=Pendulum", "rl=ppo", "policy=rl_randomized", "debug=smoke", "logging.progress=false",
            "rl.evaluate.video_steps=0"]


def test_run_killed_during_train_policy_resumes_from_the_last_finished_stage(compose, tmp_path, monkeypatch):
    cfg = compose(RL_SMOKE)
    original_train = PPOTrainer.train
    trained_rounds = []

    def killed_in_round_2(self, env, seed, on_batch=None):
        trained_rounds.append(seed)
        if len(trained_rounds) == 2:
            raise KeyboardInterrupt  # as if the job were killed in the middle of round 2's PPO
        return original_train(self, env, seed, on_batch)

    monkeypatch.setattr(PPOTrainer, "train", killed_in_round_2)
    with pytest.raises(KeyboardInterrupt):
        Pipeline(cfg, tmp_path).run()
    assert (tmp_path / "round_001" / "evaluate.pt").is_file() and (tmp_path / "round_002" / "score.pt").is_file()
    assert not (tmp_path / "round_002" / "train_policy.pt").exists()
    finished = {p: p.stat().st_mtime_ns for p in tmp_path.glob("round_*/*.pt")}

    monkeypatch.setattr(PPOTrainer, "train", original_train)
    calls = []
    for owner, stage in [(BayesSim, "collect"), (BayesSim, "fit"), (BayesSim, "condition"), (Pipeline, "real"),
                         (Pipeline, "score"), (PPOComponent, "train_policy"), (PPOComponent, "evaluate")]:
        original = getattr(owner, stage)
        monkeypatch.setattr(owner, stage, lambda self, ctx, _f=original, _s=stage: calls.append((_s, ctx.round)) or _f(self, ctx))
    results = Pipeline(cfg, tmp_path).run()
    assert calls == [("train_policy", 2), ("evaluate", 2)]  # nothing finished ran again
    assert all(p.stat().st_mtime_ns == t for p, t in finished.items())
    saved = json.loads((tmp_path / "results.json").read_text())
    for record in saved["rounds"]:
        ret = record["surrogate_real_return"]
        assert math.isfinite(ret["mean"]) and ret["min"] <= ret["mean"] <= ret["max"]
        assert record["rl_training"]["steps"] == 512
    assert [r["round"] for r in results["rounds"]] == [1, 2]

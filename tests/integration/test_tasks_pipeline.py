"""`debug=smoke` completes for every registered task (and ShadowHand with path signatures). Without TensorBoard's
figures (logging.figures=false): they were 40 % of these runs' CPU time, and a figure that fails never fails a run,
so drawing them here tested nothing (test_pipeline.py tests the figures)."""

import json

import pytest

from bayessim_exp import registry
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("overrides", [[f"task={name}"] for name in registry.names("task")]
                         + [["task=ShadowHand", "summarizer=signatory"]], ids=lambda o: "-".join(o))
def test_smoke_run_completes(compose, tmp_path, overrides):
    results = Pipeline(compose(overrides + ["debug=smoke", "logging.figures=false"]), tmp_path).run()
    assert [r["round"] for r in results["rounds"]] == [1, 2]
    last = results["rounds"][-1]
    assert last["log_prob_true_posterior"] is not None and last["diverged"] < last["sim_trajectories"] / 10
    assert json.loads((tmp_path / "results.json").read_text())["task"] == overrides[0].split("=")[1]

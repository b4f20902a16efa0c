"""Every summarizer through one smoke-sized pipeline round (the CLI's `summarizer=<name> debug=smoke`)."""

import math

import pytest

from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("summarizer", ["start", "waypoints", "corr", "corrdiff", "signatory", "learned"])
def test_pipeline_runs_with_each_summarizer(compose, tmp_path, summarizer):
    cfg = compose(["debug=smoke", "logging.progress=false", "rounds=1", f"summarizer={summarizer}"])
    results = Pipeline(cfg, tmp_path).run()
    assert results["summarizer"] == summarizer
    last = results["rounds"][-1]
    assert last["diverged"] == 0
    assert all(math.isfinite(v) for v in last["posterior_mean"].values())

"""method=sysid through the pipeline: the same results fields as the other methods, near the truth on Pendulum,
resuming."""

import json

import pytest

from bayessim_exp import api
from bayessim_exp.inference.sysid.fit import SysidFit
from bayessim_exp.inference.sysid.method import Sysid
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow

SMOKE = ["method=sysid", "debug=smoke", "logging.progress=false"]


@pytest.mark.parametrize("task, dim", [("Pendulum", 2), ("Cartpole", 13)])
def test_smoke_run_scores_like_a_posterior(compose, tmp_path, task, dim):
    cfg = compose(SMOKE + [f"task={task}"])
    results = Pipeline(cfg, tmp_path).run()
    assert json.loads((tmp_path / "results.json").read_text()) == json.loads(json.dumps(results))
    assert results["method"] == "sysid" and len(results["rounds"]) == cfg.rounds
    for rnd in results["rounds"]:
        for key in ("posterior_mean", "posterior_std", "prior_std", "log_prob_true_posterior", "log_prob_true_prior",
                    "log_prob_gain", "real_trajectories", "sim_trajectories", "diverged"):
            assert rnd[key] is not None, key
        assert set(rnd["seconds"]) == {"real", "fit", "score"}
        # every solver evaluation replays every real trajectory recorded so far
        assert rnd["sim_trajectories"] % rnd["real_trajectories"] == 0 and rnd["sim_trajectories"] > 0
        fitted = rnd["sysid"]
        assert set(fitted["estimate"]) == set(results["param_names"])
        assert fitted["objective_final"] <= fitted["objective_start"]
    posterior = api.load_run(tmp_path).posterior()
    assert posterior.sample((5,)).shape == (5, dim)


def test_pendulum_smoke_finds_the_true_parameters(compose, tmp_path):
    results = Pipeline(compose(SMOKE), tmp_path).run()
    true, last = results["true_params"], results["rounds"][-1]
    for name in results["param_names"]:
        assert abs(last["sysid"]["estimate"][name] - true[name]) < 1e-5
        assert abs(last["posterior_mean"][name] - true[name]) < 3 * last["posterior_std"][name]
    assert last["log_prob_gain"] > 5.0


def test_a_fit_that_leaves_residuals_as_large_as_the_observations_hands_on_the_prior(compose, tmp_path, monkeypatch):
    # what a local minimum every start fell into looks like: a noise estimate of the observations' own spread
    monkeypatch.setattr(SysidFit, "noise_var", property(lambda self: 1.0))
    results = Pipeline(compose(SMOKE), tmp_path).run()
    for rnd in results["rounds"]:
        assert rnd["sysid"]["failed"] and rnd["sysid"]["noise_std"] == 1.0
        assert rnd["posterior_std"] == rnd["prior_std"]
        assert rnd["log_prob_gain"] == pytest.approx(0.0, abs=1e-9)


def test_a_killed_run_resumes_without_repeating_the_fit(compose, tmp_path, monkeypatch):
    cfg = compose(SMOKE)
    Pipeline(cfg, tmp_path).run(stop_after=(1, "fit"))
    calls = []
    original = Sysid.fit
    monkeypatch.setattr(Sysid, "fit", lambda self, ctx: calls.append(ctx.round) or original(self, ctx))
    results = Pipeline(cfg, tmp_path).run()
    assert calls == [2] and [r["round"] for r in results["rounds"]] == [1, 2]

"""method=simopt through the pipeline: the same results fields as BayesSim, the KL bound, resuming."""

import json

import pytest

from bayessim_exp import api
from bayessim_exp.inference.simopt.method import SimOpt
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow

SMOKE = ["method=simopt", "debug=smoke", "logging.progress=false"]


def test_cartpole_smoke_scores_like_a_posterior_and_keeps_every_update_within_the_kl_bound(compose, tmp_path):
    cfg = compose(SMOKE + ["task=Cartpole"])
    results = Pipeline(cfg, tmp_path).run()
    assert json.loads((tmp_path / "results.json").read_text()) == json.loads(json.dumps(results))
    assert results["method"] == "simopt" and len(results["rounds"]) == cfg.rounds
    for rnd in results["rounds"]:
        for key in ("posterior_mean", "posterior_std", "prior_std", "log_prob_true_posterior", "log_prob_true_prior",
                    "log_prob_gain", "real_trajectories", "sim_trajectories", "diverged"):
            assert rnd[key] is not None, key
        assert set(rnd["seconds"]) == {"real", "search", "score"}
        updates = rnd["simopt_updates"]
        assert len(updates) == cfg.method.updates
        assert all(u["gaussian_kl"] <= cfg.method.kl_bound + 1e-9 and u["weights_kl"] <= cfg.method.kl_bound + 1e-9
                   for u in updates)
        # each sample is rolled out from every real trajectory recorded so far
        per_update = cfg.collect.trajectories // cfg.method.updates
        assert rnd["sim_trajectories"] == per_update * cfg.method.updates * rnd["real_trajectories"]
    # the run's distribution reads back as any posterior does
    posterior = api.load_run(tmp_path).posterior()
    assert posterior.sample((5,)).shape == (5, 13)


def test_pendulum_smoke_moves_towards_the_true_parameters(compose, tmp_path):
    results = Pipeline(compose(SMOKE + ["task=Pendulum"]), tmp_path).run()
    true, last = results["true_params"], results["rounds"][-1]
    low, high = results["prior"]["low"], results["prior"]["high"]
    for name in results["param_names"]:
        prior_error = abs(0.5 * (low[name] + high[name]) - true[name])
        assert abs(last["posterior_mean"][name] - true[name]) < 0.5 * prior_error + 0.02 * (high[name] - low[name])
    assert last["log_prob_gain"] > 2.0


def test_a_killed_run_resumes_without_repeating_the_search(compose, tmp_path, monkeypatch):
    cfg = compose(SMOKE)
    Pipeline(cfg, tmp_path).run(stop_after=(1, "search"))
    calls = []
    original = SimOpt.search
    monkeypatch.setattr(SimOpt, "search", lambda self, ctx: calls.append(ctx.round) or original(self, ctx))
    results = Pipeline(cfg, tmp_path).run()
    assert calls == [2] and [r["round"] for r in results["rounds"]] == [1, 2]

"""The model-mismatch verdict: summaries outside the simulated range, replays and dispersion."""

import logging

import torch

from bayessim_exp.diagnostics.mismatch import mismatch_report, summaries_outside


def test_summaries_drawn_like_the_simulations_are_not_flagged_and_far_ones_are():
    g = torch.Generator().manual_seed(0)
    x_sim = torch.randn(10_000, 80, generator=g)
    alike = torch.randn(200, 80, generator=g)
    outside = summaries_outside(alike, x_sim)
    # each feature is outside with probability 2 / 10001: about 1.6 % of summaries have one, none has many
    assert sum(c > 0 for c in outside["features_outside"]) < 10
    assert min(outside["p_value"]) > 0.01 / 200
    shifted = alike[:2].clone()
    shifted[:, :10] += 10.0
    far = summaries_outside(shifted, x_sim)
    assert far["features_outside"] == [10, 10] and max(far["p_value"]) < 1e-20


def test_every_sign_is_named_in_the_report_and_the_log(caplog):
    caplog.set_level(logging.WARNING)
    clean = mismatch_report(2, {"features_outside": [0, 0], "p_value": [1.0, 1.0]},
                            {"flagged": [], "distance_posterior": [0.01, 0.01], "distance_prior": [1.0, 1.0]},
                            {"birge_ratio": 0.8, "p_value": 0.6}, alpha=0.01)
    assert clean["flagged"] is False and not caplog.text
    report = mismatch_report(3, {"features_outside": [0, 7], "p_value": [1.0, 1e-9]},
                             {"flagged": [1], "distance_posterior": [0.01, 0.4], "distance_prior": [1.0, 1.0]},
                             {"birge_ratio": 19.0, "p_value": 1e-20}, alpha=0.01)
    assert report["flagged"] is True and len(report["reasons"]) == 3
    assert "real summaries [1] have [7] features outside" in caplog.text
    assert "real trajectories [1]" in caplog.text and "[0.4] of their distance" in caplog.text
    assert "Birge ratio 19.00" in caplog.text and "round 3: possible model mismatch" in caplog.text

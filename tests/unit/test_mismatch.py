"""The model-mismatch verdict: summaries outside the simulated range, replays and dispersion."""

import logging

import pytest
import torch

from bayessim_exp.diagnostics.mismatch import mismatch_report, summaries_outside


def _correlated(n: int, g: torch.Generator) -> torch.Tensor:
    """80 features sharing one heavy-tailed factor: outside the range together, as real summaries' features are."""
    common = torch.randn(n, 1, generator=g) ** 3
    return common + 0.1 * torch.randn(n, 80, generator=g)


def test_summaries_drawn_like_the_simulations_get_uniform_p_values_even_with_correlated_features():
    """2,000 'real' summaries exchangeable with the simulations: at most a chance share at or below each level
    (counts are discrete, so the p-values are conservative)."""
    g = torch.Generator().manual_seed(0)
    x_train, x_held, alike = _correlated(9000, g), _correlated(1000, g), _correlated(2000, g)
    p = torch.tensor(summaries_outside(alike, x_train, x_held)["p_value"])
    for level in (0.01, 0.05, 0.2):
        share = float((p <= level).double().mean())
        assert share <= level + 3 * (level * (1 - level) / 2000) ** 0.5, (level, share)


def test_summaries_far_from_the_simulations_are_flagged():
    g = torch.Generator().manual_seed(1)
    x_train, x_held = _correlated(9000, g), _correlated(1000, g)
    shifted = _correlated(2, g)
    shifted[:, :10] += 1e4
    far = summaries_outside(shifted, x_train, x_held)
    assert far["features_outside"] == [10, 10] and far["p_value"] == pytest.approx([1 / 1001] * 2)


def test_every_sign_is_named_in_the_report_and_the_log(caplog):
    caplog.set_level(logging.WARNING)
    clean = mismatch_report(2, {"features_outside": [0, 0], "p_value": [1.0, 1.0]},
                            {"flagged": [], "excess_ratio": [0.01, 0.01], "max_distance_ratio": 0.15},
                            {"birge_ratio": 0.8, "p_value": 0.6}, alpha=0.01)
    assert clean["flagged"] is False and not caplog.text
    report = mismatch_report(3, {"features_outside": [0, 7], "p_value": [1.0, 1e-4]},
                             {"flagged": [1], "excess_ratio": [0.01, 0.4], "max_distance_ratio": 0.15},
                             {"birge_ratio": 19.0, "p_value": 1e-20}, alpha=0.01)
    assert report["flagged"] is True and len(report["reasons"]) == 3
    assert "real summaries [1] have [7] features outside" in caplog.text
    assert "real trajectories [1]" in caplog.text and "[0.4] of their distance" in caplog.text
    assert "Birge ratio 19.00" in caplog.text and "round 3: possible model mismatch" in caplog.text

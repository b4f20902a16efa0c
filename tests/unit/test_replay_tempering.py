"""Widening by the model error: the temperature whose posterior holds the model error's covariance, capped at
the prior's, then halved while the real data's implied parameters lie outside."""

import types

import pytest
import torch

from bayessim_exp.inference.bayessim.replay_tempering import (
    TEMPERATURE_FLOOR,
    model_error_temperature,
    temper_to_replays,
)


def _check(posterior_var, error_var, p_value=0.5):
    return types.SimpleNamespace(posterior_covariance=torch.diag(torch.tensor(posterior_var, dtype=torch.float64)),
                                 model_error_covariance=torch.diag(torch.tensor(error_var, dtype=torch.float64)),
                                 p_value=[p_value], too_narrow=[0] if p_value <= 0.01 else [])


PRIOR = torch.eye(2, dtype=torch.float64)


def test_no_model_error_no_widening():
    assert model_error_temperature(_check([0.01, 0.01], [0.0, 0.0]), PRIOR) == 1.0


def test_the_widest_direction_sets_the_temperature():
    """Sigma_post / tau >= Sigma_error: tau = 0.01 / 0.04 along the first parameter, the binding one."""
    assert model_error_temperature(_check([0.01, 0.01], [0.04, 1e-4]), PRIOR) == pytest.approx(0.25)


def test_a_model_error_wider_than_the_prior_is_capped_at_the_prior():
    assert model_error_temperature(_check([0.01, 0.5], [100.0, 0.0]), PRIOR) == pytest.approx(0.01)


def test_halved_while_too_narrow_from_the_model_error_temperature():
    tried = []

    def condition_at(tau):
        tried.append(tau)
        return tau

    def check(tau):  # too narrow until tau is about 1/16
        return _check([0.01 / tau, 0.01 / tau], [0.04, 0.0], p_value=0.5 if tau < 0.07 else 0.0)

    post, first, last, tau, tries = temper_to_replays(condition_at, check, PRIOR)
    assert tried == pytest.approx([1.0, 0.25, 0.125, 0.0625]) and tau == post == pytest.approx(0.0625)
    assert [t["temperature"] for t in tries] == tried and first.p_value == [0.0] and last.p_value == [0.5]


def test_never_below_the_floor():
    post, *_, tau, _ = temper_to_replays(lambda tau: tau, lambda tau: _check([1.0, 1.0], [0.0, 0.0], p_value=0.0), PRIOR)
    assert tau == TEMPERATURE_FLOOR

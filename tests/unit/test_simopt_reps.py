"""REPS: temperature and weights against a direct minimisation of the dual, and the KL-bounded Gaussian step."""

import math

import numpy as np
import pytest
import scipy.optimize
import scipy.special
import torch
from torch.distributions import MultivariateNormal, kl_divergence

from bayessim_exp.inference.simopt.reps import Gaussian, floor_covariance, reps_update, reps_weights, weighted_fit


def scipy_dual(log_eta: float, costs: np.ndarray, epsilon: float) -> float:
    """g(eta) = eta eps + eta log mean exp(-c / eta), written independently of the module."""
    eta = math.exp(log_eta)
    return eta * epsilon + eta * (scipy.special.logsumexp(-costs / eta) - math.log(len(costs)))


COSTS = np.array([3.1, 0.4, 2.2, 5.0, 0.9, 1.7, 4.4, 0.6])


@pytest.mark.parametrize("epsilon", [0.1, 0.5, 1.0])
def test_temperature_and_weights_match_scipy_minimisation_of_the_dual(epsilon):
    res = scipy.optimize.minimize_scalar(scipy_dual, bounds=(-8, 8), args=(COSTS, epsilon), method="bounded",
                                         options={"xatol": 1e-12})
    eta = math.exp(res.x)
    expected = scipy.special.softmax(-COSTS / eta)
    rw = reps_weights(torch.tensor(COSTS), epsilon, min_temperature=1e-6)
    assert rw.temperature == pytest.approx(eta, rel=1e-5)
    np.testing.assert_allclose(rw.weights.numpy(), expected, rtol=1e-5, atol=1e-9)
    # at an interior optimum the weights use up the whole KL budget
    assert rw.kl == pytest.approx(epsilon, abs=1e-9)


def test_minimum_temperature_binds_when_epsilon_exceeds_what_the_weights_can_reach():
    costs = torch.tensor(COSTS)
    # KL(p || uniform) <= log N, so epsilon = 5 > log 8 is never reached: eta goes to its floor
    rw = reps_weights(costs, 5.0, min_temperature=0.01)
    assert rw.temperature == pytest.approx(0.01 * float(costs.std()))
    assert rw.weights.argmax() == costs.argmin()


def test_weights_do_not_depend_on_the_costs_scale_or_offset():
    costs = torch.tensor(COSTS)
    a, b = reps_weights(costs, 0.7, 1e-3), reps_weights(1000 * costs + 17, 0.7, 1e-3)
    torch.testing.assert_close(a.weights, b.weights, rtol=1e-6, atol=1e-9)
    assert b.temperature == pytest.approx(1000 * a.temperature, rel=1e-6)


def test_equal_costs_give_uniform_weights():
    rw = reps_weights(torch.ones(5), 1.0, 1e-3)
    torch.testing.assert_close(rw.weights, torch.full((5,), 0.2, dtype=torch.float64))
    assert rw.kl == 0.0


@pytest.mark.parametrize("costs, match", [(torch.tensor([1.0]), "at least 2"),
                                          (torch.tensor([1.0, float("nan")]), "finite")])
def test_bad_costs_are_refused(costs, match):
    with pytest.raises(ValueError, match=match):
        reps_weights(costs, 1.0, 1e-3)


def test_gaussian_kl_matches_torch():
    g = torch.Generator().manual_seed(0)
    a_factor, b_factor = torch.randn(3, 3, generator=g, dtype=torch.float64), torch.randn(3, 3, generator=g, dtype=torch.float64)
    a = Gaussian(torch.randn(3, generator=g, dtype=torch.float64), a_factor @ a_factor.T + 0.1 * torch.eye(3))
    b = Gaussian(torch.randn(3, generator=g, dtype=torch.float64), b_factor @ b_factor.T + 0.1 * torch.eye(3))
    expected = kl_divergence(MultivariateNormal(a.mean, a.cov), MultivariateNormal(b.mean, b.cov))
    assert a.kl(b) == pytest.approx(float(expected), rel=1e-10)


def test_weighted_fit_is_the_weighted_mean_and_covariance():
    theta = torch.tensor([[0.0, 1.0], [2.0, 1.0], [4.0, 7.0]], dtype=torch.float64)
    w = torch.tensor([0.5, 0.25, 0.25], dtype=torch.float64)
    mean, cov = weighted_fit(theta, w)
    torch.testing.assert_close(mean, torch.tensor([1.5, 2.5], dtype=torch.float64))
    d = theta - mean
    torch.testing.assert_close(cov, sum(w[i] * torch.outer(d[i], d[i]) for i in range(3)))


def test_floor_lifts_only_the_collapsed_direction():
    v = torch.tensor([1.0, 1.0], dtype=torch.float64) / math.sqrt(2)
    cov = 4.0 * torch.outer(v, v) + 1e-8 * torch.eye(2, dtype=torch.float64)  # collapsed across v
    floored = floor_covariance(cov, torch.tensor([0.1, 0.1], dtype=torch.float64))
    values = torch.linalg.eigvalsh(floored)
    assert values[0] == pytest.approx(0.01) and values[1] == pytest.approx(4.0 + 1e-8)
    # already above the floor: unchanged
    torch.testing.assert_close(floor_covariance(floored, torch.tensor([0.05, 0.05], dtype=torch.float64)), floored)


def test_gaussian_step_is_pulled_back_to_the_kl_bound():
    """Few samples and a near-greedy temperature: the weighted fit alone would break the bound."""
    g = torch.Generator().manual_seed(1)
    old = Gaussian(torch.zeros(3, dtype=torch.float64), torch.eye(3, dtype=torch.float64))
    theta = old.sample(30, g)
    costs = ((theta - 2.0) ** 2).sum(1)
    min_std = torch.full((3,), 1e-3, dtype=torch.float64)
    mean, cov = weighted_fit(theta, reps_weights(costs, 1.0, 1e-3).weights)
    assert Gaussian(mean, floor_covariance(cov, min_std)).kl(old) > 1.0  # the unbounded fit
    step = reps_update(old, theta, costs, 1.0, 1e-3, min_std)
    assert step.step_fraction < 1.0
    exact = kl_divergence(MultivariateNormal(step.gaussian.mean, step.gaussian.cov),
                          MultivariateNormal(old.mean, old.cov))
    assert float(exact) <= 1.0 + 1e-9 and float(exact) == pytest.approx(1.0, abs=1e-6)
    assert step.weights_kl == pytest.approx(1.0, abs=1e-9)
    assert (step.gaussian.mean > 0).all()  # towards the low-cost corner


def test_a_small_step_is_taken_whole():
    g = torch.Generator().manual_seed(2)
    old = Gaussian(torch.zeros(2, dtype=torch.float64), torch.eye(2, dtype=torch.float64))
    theta = old.sample(4000, g)
    step = reps_update(old, theta, theta[:, 0], 0.05, 1e-3, torch.full((2,), 1e-3, dtype=torch.float64))
    assert step.step_fraction == 1.0 and step.gaussian_kl <= 0.05 + 1e-9
    assert step.gaussian.mean[0] < -0.1

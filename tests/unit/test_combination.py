"""Combining several real trajectories: tempering is exact for Gaussians, Cochran's Q has its known
chi^2 behaviour, and disagreeing trajectories widen the combined posterior instead of narrowing it."""

import math

import pytest
import torch

from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.inference.bayessim.combination import combine, dispersion
from bayessim_exp.inference.bayessim.correction import posterior

BOX = BoxUniform(-50 * torch.ones(2, dtype=torch.float64), 50 * torch.ones(2, dtype=torch.float64))
COV = torch.tensor([[0.04, 0.01], [0.01, 0.02]], dtype=torch.float64)


def gaussian(mean, cov=COV):
    return GaussianMixture(torch.zeros(1), torch.as_tensor(mean, dtype=torch.float64)[None], cov[None])


def test_a_tempered_product_of_gaussians_is_the_product_with_covariance_divided_by_tau():
    qs = [gaussian([0.1, 0.0]), gaussian([0.0, 0.2]), gaussian([-0.1, 0.1])]
    tau = 0.25
    post = posterior(qs, BOX, temperature=tau)
    # exact: the product of n equal-covariance Gaussians is N(mean of means, C / n); tempering divides by tau
    mean = torch.tensor([0.0, 0.1], dtype=torch.float64)
    exact = torch.distributions.MultivariateNormal(mean, COV / (3 * tau))
    theta = mean + 0.3 * torch.randn(50, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    assert torch.allclose(post.log_prob(theta), exact.log_prob(theta), atol=1e-2)  # mass inside by Monte Carlo


def test_the_temperature_must_be_in_the_unit_interval():
    with pytest.raises(ValueError, match="temperature"):
        posterior([gaussian([0.0, 0.0])], BOX, temperature=1.5)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_cochran_q_of_consistent_posteriors_follows_chi2():
    """Means drawn from N(theta, C_i), posteriors N(mean_i, C_i): E[Q] = dof and p-values uniform."""
    g = torch.Generator().manual_seed(0)
    scale = torch.linalg.cholesky(COV)
    birge, p_values = [], []
    for rep in range(40):
        means = (torch.randn(5, 2, generator=g, dtype=torch.float64) @ scale.T).tolist()
        spread = dispersion([posterior([gaussian(m)], BOX, seed=rep) for m in means], seed=rep)
        assert spread.dof == 8
        birge.append(spread.birge_ratio)
        p_values.append(spread.p_value)
    # the Birge ratio of 40 sets averages 1 with standard error sqrt(2 / 8 / 40) = 0.08
    assert abs(sum(birge) / len(birge) - 1.0) < 0.25
    assert 0.3 < sum(p_values) / len(p_values) < 0.7


def test_disagreeing_trajectories_widen_the_posterior_as_much_as_they_scatter():
    """Means scattered 3x wider than the per-trajectory posteriors: the product is 3x overconfident, the
    dispersion combination is not."""
    g = torch.Generator().manual_seed(1)
    scale = 3 * torch.linalg.cholesky(COV)
    means = (torch.randn(20, 2, generator=g, dtype=torch.float64) @ scale.T).tolist()
    qs = [gaussian(m) for m in means]
    product, spread = combine("product", qs, BOX)
    tempered, _ = combine("dispersion", qs, BOX)
    assert 5 < spread.birge_ratio < 15  # 9 expected
    assert spread.p_value < 1e-6
    ratio = (tempered.stddev / product.stddev) ** 2
    assert torch.allclose(ratio, torch.full((2,), spread.birge_ratio, dtype=torch.float64), rtol=0.1)
    # the truth (the origin) is far outside the product's 90 % region but inside the tempered one's
    origin = torch.zeros(1, 2, dtype=torch.float64)
    chi2_90 = -2 * math.log(0.1)  # the 90 % quantile of chi^2 with 2 degrees of freedom
    for post, inside in ((product, False), (tempered, True)):
        mean, cov = post.sample((20_000,)).mean(0), torch.cov(post.sample((20_000,)).T)
        distance = float(mean @ torch.linalg.solve(cov, mean))
        assert (distance < chi2_90) == inside, (distance, inside)
    assert tempered.log_prob(origin) > product.log_prob(origin)


def test_one_trajectory_is_not_tempered():
    q = gaussian([0.3, -0.2])
    post, spread = combine("dispersion", [q], BOX)
    assert spread is None
    theta = torch.tensor([[0.3, -0.2], [0.5, 0.0]], dtype=torch.float64)
    assert torch.allclose(post.log_prob(theta), posterior([q], BOX).log_prob(theta))


def test_an_unknown_combination_is_refused():
    with pytest.raises(ValueError, match="allowed: dispersion, product"):
        combine("average", [gaussian([0.0, 0.0])], BOX)

"""SNPE-A correction and the combination of several real summaries, against closed-form posteriors."""

import math

import pytest
import torch
from linear_gaussian import LinearGaussian

from bayessim_exp.distributions.importance import ImportancePosterior
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.truncated_prior import TruncatedPrior
from bayessim_exp.inference.bayessim.correction import posterior

A = torch.tensor([[1.0, 0.5], [-0.3, 2.0], [0.7, 0.0]])
SIM = LinearGaussian(A, torch.tensor([0.1, -0.2, 0.3]), 0.2 * torch.eye(3))
MEAN0, STD0 = torch.tensor([1.0, -0.5]), torch.tensor([1.5, 0.8])
PRIOR = GaussianPrior(MEAN0, STD0)


def _single(mean, cov) -> GaussianMixture:
    return GaussianMixture(torch.zeros(1), mean[None], cov[None])


def _exact_q(proposal_mean, proposal_cov, x) -> GaussianMixture:
    """q(theta | x) a perfect model trained under the proposal would give: the proposal posterior."""
    return _single(*SIM.posterior(proposal_mean, proposal_cov, x[None]))


def test_snpe_a_recovers_prior_posterior_from_proposal_posterior():
    x = SIM.simulate(torch.tensor([[1.2, -0.4]]), seed=0)[0]
    prop_mean, prop_cov = torch.tensor([1.1, -0.3]), torch.diag(torch.tensor([0.3, 0.2]) ** 2)
    proposal = _single(prop_mean, prop_cov)
    post = posterior([_exact_q(prop_mean, prop_cov, x)], PRIOR, proposal)
    mean, cov = SIM.posterior(MEAN0, PRIOR.covariance_matrix, x[None])
    assert isinstance(post, GaussianMixture)
    torch.testing.assert_close(post.mean, mean, atol=1e-9, rtol=1e-9)
    torch.testing.assert_close(post.covariance, cov, atol=1e-9, rtol=1e-9)


def test_snpe_a_keeps_mixture_weights_exact():
    """A two-component q: the corrected weights must equal the closed-form ones, not the raw ones."""
    prop = _single(torch.zeros(1), torch.eye(1) * 0.5)
    q = GaussianMixture(torch.log(torch.tensor([0.3, 0.7])), torch.tensor([[-1.0], [1.0]]), torch.tensor([[[0.2]], [[0.3]]]))
    prior = GaussianPrior(torch.zeros(1), torch.ones(1) * 2.0)
    post = posterior([q], prior, prop)
    grid = torch.linspace(-8, 8, 20001, dtype=torch.float64)[:, None]
    dens = (q.log_prob(grid) + prior.log_prob(grid) - prop.log_prob(grid)).exp()
    dens = dens / torch.trapezoid(dens, grid[:, 0])
    torch.testing.assert_close(post.log_prob(grid).exp(), dens, atol=1e-6, rtol=1e-5)


def test_several_observations_match_the_n_observation_posterior():
    theta_true = torch.tensor([[0.8, -0.2]])
    xs = SIM.simulate(theta_true.expand(5, 2), seed=1)
    qs = [_exact_q(MEAN0, PRIOR.covariance_matrix, x) for x in xs]  # trained under the prior itself
    post = posterior(qs, PRIOR, PRIOR)
    mean, cov = SIM.posterior(MEAN0, PRIOR.covariance_matrix, xs)
    torch.testing.assert_close(post.mean, mean, atol=1e-9, rtol=1e-9)
    torch.testing.assert_close(post.covariance, cov, atol=1e-9, rtol=1e-9)


def test_several_observations_with_a_proposal_and_a_uniform_prior():
    xs = SIM.simulate(torch.tensor([[0.9, -0.1]]).expand(3, 2), seed=2)
    prop_mean, prop_cov = torch.tensor([0.8, 0.0]), torch.diag(torch.tensor([0.5, 0.4]) ** 2)
    qs = [_exact_q(prop_mean, prop_cov, x) for x in xs]
    box = BoxUniform(torch.tensor([-5.0, -5.0], dtype=torch.float64), torch.tensor([5.0, 5.0], dtype=torch.float64))
    post = posterior(qs, box, _single(prop_mean, prop_cov))
    # a flat prior is the limit of a very broad Gaussian; the box is far away from the mass
    mean, cov = SIM.posterior(torch.zeros(2), 1e8 * torch.eye(2), xs)
    assert isinstance(post, TruncatedMixture) and post.log_mass_inside == 0.0
    torch.testing.assert_close(post.mixture.mean, mean, atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(post.mixture.covariance, cov, atol=1e-6, rtol=1e-6)


def _exact_on_box(q, prop, low, high) -> tuple[torch.Tensor, torch.Tensor]:
    """A grid over the one-parameter box and the mean of q / prop restricted to it (the posterior under a flat prior)."""
    grid = torch.linspace(low.item(), high.item(), 3001, dtype=torch.float64)[:, None]
    dens = (q.log_prob(grid) - prop.log_prob(grid)).exp()
    return grid, torch.trapezoid(dens * grid[:, 0], grid[:, 0]) / torch.trapezoid(dens, grid[:, 0])


def test_non_positive_definite_correction_falls_back_to_importance_sampling(caplog):
    """q broader than the proposal: 1/p~ outgrows q, no Gaussian; exact on the box by importance sampling."""
    low, high = torch.tensor([-1.0], dtype=torch.float64), torch.tensor([2.0], dtype=torch.float64)
    q = _single(torch.tensor([0.5]), torch.eye(1))
    prop = _single(torch.tensor([0.0]), 0.25 * torch.eye(1))
    post = posterior([q], BoxUniform(low, high), prop)
    assert isinstance(post, ImportancePosterior)
    assert "not positive definite" in caplog.text
    grid, exact_mean = _exact_on_box(q, prop, low, high)
    assert abs(torch.trapezoid(post.log_prob(grid).exp(), grid[:, 0]).item() - 1.0) < 0.02
    assert abs(post.sample((20000,)).mean().item() - exact_mean.item()) < 0.02
    assert math.isclose(post.mean.item(), exact_mean.item(), abs_tol=0.01)


def test_importance_sampling_covers_the_box_when_the_conditional_s_mass_lies_outside_it():
    """A model fitted as its mixture truncated to the box (models/box_mass.py) may put a component's mean far outside
    it: the conditionals' Gaussians then draw no base point inside, and the prior's box must cover the target."""
    low, high = torch.tensor([-1.0], dtype=torch.float64), torch.tensor([2.0], dtype=torch.float64)
    q = _single(torch.tensor([12.0]), 4.0 * torch.eye(1))  # inside the box: rising toward the upper face
    prop = _single(torch.tensor([0.0]), 0.25 * torch.eye(1))
    post = posterior([q], BoxUniform(low, high), prop)
    assert isinstance(post, ImportancePosterior)
    grid, exact_mean = _exact_on_box(q, prop, low, high)
    assert math.isclose(post.mean.item(), exact_mean.item(), abs_tol=0.02)
    assert abs(torch.trapezoid(post.log_prob(grid).exp(), grid[:, 0]).item() - 1.0) < 0.02


def test_moment_matched_proposal_keeps_the_correction_in_closed_form():
    from bayessim_exp.inference.bayessim.proposals import moment_matched

    low, high = torch.tensor([-3.0, -3.0], dtype=torch.float64), torch.tensor([3.0, 3.0], dtype=torch.float64)
    box = BoxUniform(low, high)
    previous = TruncatedMixture(GaussianMixture(torch.zeros(2), torch.tensor([[0.0, 0.0], [1.0, 0.5]]),
                                                torch.eye(2).expand(2, 2, 2) * 0.3), low, high)
    proposal = moment_matched(previous, low, high)
    assert isinstance(proposal, TruncatedMixture) and proposal.mixture.num_components == 1
    torch.testing.assert_close(proposal.mixture.mean, previous.mean, atol=0.03, rtol=0)
    q = _single(torch.tensor([0.4, 0.2]), 0.05 * torch.eye(2))
    post = posterior([q], box, proposal)
    assert isinstance(post, TruncatedMixture)
    grid_mean = _box_grid_mean(lambda t: q.log_prob(t) - proposal.log_prob(t), low, high)
    torch.testing.assert_close(post.mixture.mean, grid_mean, atol=1e-3, rtol=0)


def test_truncated_prior_proposal_needs_no_correction():
    from bayessim_exp.distributions.restricted import Restricted

    low, high = torch.tensor([-3.0, -3.0], dtype=torch.float64), torch.tensor([3.0, 3.0], dtype=torch.float64)
    box = BoxUniform(low, high)
    previous = TruncatedMixture(_single(torch.tensor([0.5, 0.0]), 0.2 * torch.eye(2)), low, high)
    proposal = TruncatedPrior(box, previous)
    draws = proposal.sample((2000,))
    assert (previous.log_prob(draws) >= proposal.threshold).all()
    q = _single(torch.tensor([0.4, 0.2]), 0.05 * torch.eye(2))
    assert isinstance(posterior([q], box, proposal), TruncatedMixture)  # q itself, only truncated
    flow_like = torch.distributions.MultivariateNormal(torch.tensor([0.4, 0.2]), 0.05 * torch.eye(2))
    assert isinstance(posterior([flow_like], box, proposal), Restricted)


def _box_grid_mean(log_density, low, high, n=401):
    g0 = torch.linspace(low[0], high[0], n, dtype=torch.float64)
    g1 = torch.linspace(low[1], high[1], n, dtype=torch.float64)
    grid = torch.stack(torch.meshgrid(g0, g1, indexing="ij"), -1).reshape(-1, 2)
    w = torch.softmax(log_density(grid), 0)
    return (w[:, None] * grid).sum(0)


def test_truncation_to_a_region_with_almost_no_prior_mass_is_refused():
    # 30 parameters, posterior std 1/20 of the prior's width: its region is ~1e-30 of the prior
    d = 30
    prior = BoxUniform(torch.zeros(d, dtype=torch.float64), torch.ones(d, dtype=torch.float64))
    narrow = GaussianMixture(torch.zeros(1), torch.full((1, d), 0.5), (0.05**2) * torch.eye(d)[None])
    with pytest.raises(ValueError, match="too little to sample by rejection"):
        TruncatedPrior(prior, narrow)

"""Proposals (inference/bayessim/proposals.py): each option's rule for round r's proposal from what round r - 1
handed on, its fallbacks to the prior, whether rounds pool, and options registered from outside."""

import logging

import pytest
import torch

from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
from bayessim_exp.distributions.truncated_prior import TruncatedPrior
from bayessim_exp.errors import ConfigError
from bayessim_exp.inference.bayessim.proposals import (
    PROPOSALS,
    GaussianProposal,
    PosteriorProposal,
    PriorProposal,
    Proposal,
    ProposalInputs,
    TruncatedProposal,
    moment_matched,
    proposal_named,
    register_proposal,
)
from bayessim_exp.registry import parse_params

LOW, HIGH = torch.tensor([-3.0, -3.0], dtype=torch.float64), torch.tensor([3.0, 3.0], dtype=torch.float64)
PRIOR = BoxUniform(LOW, HIGH)


def _previous() -> TruncatedMixture:
    """A fresh posterior for every use: a truncated mixture's draws without a generator continue its own stream."""
    return TruncatedMixture(GaussianMixture(torch.zeros(2), torch.tensor([[0.5, 0.0], [1.0, 0.3]]),
                                            0.2 * torch.eye(2).repeat(2, 1, 1)), LOW, HIGH)


INPUTS = ProposalInputs(round=2, prior=PRIOR, probit=None, seed=7)


def test_the_built_in_options_and_whether_their_rounds_pool():
    assert list(PROPOSALS) == ["prior", "posterior", "gaussian", "truncated"]
    assert {name: proposal_named(name).pools_rounds for name in PROPOSALS} == {
        "prior": True, "posterior": False, "gaussian": False, "truncated": True}


def test_every_option_simulates_from_the_prior_after_a_guard_fallback():
    for name in PROPOSALS:
        assert proposal_named(name).build(PRIOR, INPUTS) is None, name


def test_prior_and_posterior():
    previous = _previous()
    assert PriorProposal().build(previous, INPUTS) is None
    assert PosteriorProposal().build(previous, INPUTS) is previous


def test_gaussian_moment_matches_in_the_box_with_the_rounds_seed():
    proposal = GaussianProposal().build(_previous(), INPUTS)
    assert isinstance(proposal, TruncatedMixture) and proposal.mixture.num_components == 1
    torch.testing.assert_close(proposal.mixture.means, moment_matched(_previous(), LOW, HIGH, seed=7).mixture.means)
    torch.testing.assert_close(proposal.mixture.mean, _previous().mixture.mean, atol=0.03, rtol=0)


def test_gaussian_moment_matches_in_probit_space_where_the_model_is_fitted_there():
    transform = ProbitTransform(PRIOR)
    inner = GaussianMixture(torch.zeros(2), torch.tensor([[0.5, 0.0], [-0.5, 0.2]]), 0.1 * torch.eye(2).repeat(2, 1, 1))
    proposal = GaussianProposal().build(ProbitPosterior(inner, transform), ProposalInputs(2, PRIOR, transform, 7))
    assert isinstance(proposal, ProbitPosterior) and proposal.transform is transform
    assert isinstance(proposal.inner, GaussianMixture) and proposal.inner.num_components == 1
    torch.testing.assert_close(proposal.inner.mean, inner.mean, atol=0.02, rtol=0)


def test_truncated_restricts_the_prior_and_falls_back_where_the_region_is_too_small(caplog):
    proposal = TruncatedProposal().build(_previous(), INPUTS)
    assert isinstance(proposal, TruncatedPrior) and proposal.restricts(PRIOR)
    d = 30  # posterior std 1/20 of the prior's width: its region is ~1e-30 of the prior
    prior = BoxUniform(torch.zeros(d, dtype=torch.float64), torch.ones(d, dtype=torch.float64))
    narrow = GaussianMixture(torch.zeros(1), torch.full((1, d), 0.5), (0.05**2) * torch.eye(d)[None])
    with caplog.at_level(logging.WARNING):
        assert TruncatedProposal().build(narrow, ProposalInputs(3, prior, None, 7)) is None
    assert "round 3: " in caplog.text and "simulating from the prior instead" in caplog.text


def _narrow_in_thirty_dimensions():
    """A posterior 1/20 of the prior's width in probit space, in the prior's joint tail (every multiplier of a
    [0.1, 10] range near 1): its region holds ~1e-40 of the prior. The prior, its transform, and the inner mean."""
    d = 30
    prior = BoxUniform(torch.full((d,), 0.1, dtype=torch.float64), torch.full((d,), 10.0, dtype=torch.float64))
    return prior, ProbitTransform(prior), torch.full((d,), -1.3, dtype=torch.float64)


def test_truncated_samples_a_narrow_region_in_thirty_dimensions_never_the_prior(caplog):
    prior, transform, mean = _narrow_in_thirty_dimensions()
    narrow = ProbitPosterior(GaussianMixture(torch.zeros(1), mean[None], (0.05**2) * torch.eye(30)[None]), transform)
    with caplog.at_level(logging.WARNING):
        proposal = TruncatedProposal().build(narrow, ProposalInputs(3, prior, transform, 7))
    assert isinstance(proposal, TruncatedPrior) and proposal.posterior is narrow and not caplog.text
    draws = proposal.sample((5000,), generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(narrow.log_prob(draws)).all() and (narrow.log_prob(draws) >= proposal.threshold).all()
    # the region: within 0.39 of the mean (the 99.9 % radius of 30 standard deviations of 0.05); the prior: 5.5
    assert (transform.to_probit(draws) - mean).norm(dim=1).max() < 0.45


def test_truncated_falls_back_to_the_region_of_the_posteriors_moments_where_it_has_no_mixture_form(caplog):
    prior, transform, mean = _narrow_in_thirty_dimensions()
    narrow = ProbitPosterior(GaussianPrior(mean, torch.full((30,), 0.05, dtype=torch.float64)), transform)
    with caplog.at_level(logging.WARNING):
        proposal = TruncatedProposal().build(narrow, ProposalInputs(3, prior, transform, 7))
    assert "round 3: " in caplog.text and "the Gaussian with the posterior's moments instead" in caplog.text
    assert isinstance(proposal, TruncatedPrior) and isinstance(proposal.posterior.inner, GaussianMixture)
    draws = proposal.sample((2000,), generator=torch.Generator().manual_seed(0))
    assert (transform.to_probit(draws) - mean).norm(dim=1).max() < 0.45


def test_an_unknown_option_lists_the_allowed_ones_registered_plugins_included(monkeypatch):
    with pytest.raises(ConfigError, match="allowed: prior, posterior, gaussian, truncated"):
        parse_params("method", {"name": "bayessim", "proposal": "tsnpe"})
    monkeypatch.setitem(PROPOSALS, "half_prior", None)  # removed again after the test

    @register_proposal
    class HalfPrior(Proposal):
        name = "half_prior"

    assert isinstance(proposal_named("half_prior"), HalfPrior)
    assert parse_params("method", {"name": "bayessim", "proposal": "half_prior"})[1].proposal == "half_prior"
    with pytest.raises(ConfigError, match="allowed: prior, posterior, gaussian, truncated, half_prior"):
        proposal_named("tsnpe")


def test_an_unknown_escape_lists_the_allowed_ones():
    assert parse_params("method", {"name": "bayessim", "escape": "nearest"})[1].escape == "nearest"
    with pytest.raises(ConfigError, match="escape='sysid' not allowed; allowed: linear, nearest, linear_then_posterior, posterior, none"):
        parse_params("method", {"name": "bayessim", "escape": "sysid"})

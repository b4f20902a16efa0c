"""What distributions answer for their callers, which never switch on the concrete class: the priors' marginal
CDFs, inverse CDFs, log densities and peaks (probit space), the Gaussian factor (the SNPE-A correction's closed
form), whether a proposal restricts the prior, a probit posterior's inner distribution, and torch's distributions
converted for the API."""

import math

import pytest
import torch

from bayessim_exp.distributions.base import NOT_GAUSSIAN, ParameterDistribution
from bayessim_exp.distributions.convert import as_parameter_distribution
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior, LogUniform
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
from bayessim_exp.distributions.truncated_prior import TruncatedPrior

LOW, HIGH = torch.tensor([0.1, 2.0], dtype=torch.float64), torch.tensor([10.0, 3.0], dtype=torch.float64)
LOC, SCALE = torch.tensor([1.0, 2.9], dtype=torch.float64), torch.tensor([2.0, 0.3], dtype=torch.float64)


def _inside(n=50, seed=0):
    return LOW + (HIGH - LOW) * torch.rand(n, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(seed))


def _marginals_agree_with_the_density(prior):
    theta = _inside()
    torch.testing.assert_close(prior.log_marginal(theta).sum(-1), prior.log_prob(theta))
    torch.testing.assert_close(prior.marginal_icdf(prior.marginal_cdf(theta)), theta)


def test_box_uniform_marginals_are_torchs_uniform():
    prior, theta = BoxUniform(LOW, HIGH), _inside()
    torch_uniform = torch.distributions.Uniform(LOW, HIGH)
    torch.testing.assert_close(prior.marginal_cdf(theta), torch_uniform.cdf(theta))
    torch.testing.assert_close(prior.marginal_icdf(torch.full((2,), 0.25, dtype=torch.float64)),
                               torch_uniform.icdf(torch.full((2,), 0.25, dtype=torch.float64)))
    torch.testing.assert_close(prior.log_marginal(theta), torch_uniform.log_prob(theta))
    _marginals_agree_with_the_density(prior)
    assert prior.gaussian_factor() is None  # constant on the box: nothing to divide by


def test_untruncated_gaussian_marginals_are_torchs_normal():
    prior, theta = GaussianPrior(LOC, SCALE), torch.randn(50, 2, dtype=torch.float64)
    normal = torch.distributions.Normal(LOC, SCALE)
    torch.testing.assert_close(prior.marginal_cdf(theta), normal.cdf(theta))
    c = torch.tensor([0.1, 0.8], dtype=torch.float64)
    torch.testing.assert_close(prior.marginal_icdf(c), normal.icdf(c))
    torch.testing.assert_close(prior.log_marginal(theta), normal.log_prob(theta))
    torch.testing.assert_close(prior.log_marginal(theta).sum(-1), prior.log_prob(theta))
    torch.testing.assert_close(prior.peak, LOC)
    mean, cov = prior.gaussian_factor()
    torch.testing.assert_close(mean, LOC)
    torch.testing.assert_close(cov, torch.diag(SCALE**2))


def test_truncated_gaussian_marginals_renormalise_the_normal_on_the_box():
    prior, theta = GaussianPrior(LOC, SCALE, LOW, HIGH), _inside()
    normal = torch.distributions.Normal(LOC, SCALE)
    mass = normal.cdf(HIGH) - normal.cdf(LOW)
    torch.testing.assert_close(prior.marginal_cdf(theta), (normal.cdf(theta) - normal.cdf(LOW)) / mass)
    torch.testing.assert_close(prior.log_marginal(theta), normal.log_prob(theta) - mass.log())
    torch.testing.assert_close(prior.marginal_cdf(LOW), torch.zeros(2, dtype=torch.float64))
    torch.testing.assert_close(prior.marginal_cdf(HIGH), torch.ones(2, dtype=torch.float64))
    _marginals_agree_with_the_density(prior)
    torch.testing.assert_close(prior.peak, torch.tensor([1.0, 2.9], dtype=torch.float64))  # loc, inside the box
    assert GaussianPrior(torch.tensor([20.0]), torch.tensor([1.0]), torch.tensor([0.0]), torch.tensor([1.0])).peak == 1.0
    mean, cov = prior.gaussian_factor()  # the untruncated Gaussian's: truncation only restricts the support
    torch.testing.assert_close(cov, torch.diag(SCALE**2))


def test_loguniform_marginals_are_uniform_in_log_space():
    prior, theta = LogUniform(LOW, HIGH), _inside()
    torch.testing.assert_close(prior.marginal_cdf(theta), torch.log(theta / LOW) / torch.log(HIGH / LOW))
    torch.testing.assert_close(prior.marginal_icdf(torch.full((2,), 0.5, dtype=torch.float64)), (LOW * HIGH).sqrt())
    torch.testing.assert_close(prior.log_marginal(theta), -torch.log(theta * torch.log(HIGH / LOW)))
    _marginals_agree_with_the_density(prior)
    torch.testing.assert_close(prior.peak, LOW)  # density 1 / theta: largest at the low end
    assert prior.gaussian_factor() is NOT_GAUSSIAN


def test_probit_space_reads_the_priors_answers():
    for prior in (BoxUniform(LOW, HIGH), LogUniform(LOW, HIGH), GaussianPrior(LOC, SCALE, LOW, HIGH)):
        transform, theta = ProbitTransform(prior), _inside()
        u = transform.to_probit(theta)
        torch.testing.assert_close(u, torch.special.ndtri(prior.marginal_cdf(theta)))
        torch.testing.assert_close(transform.from_probit(u), theta)
        assert transform.log_prior_peak() == pytest.approx(float(prior.log_prob(prior.peak)))
    for refused in (GaussianPrior(LOC, SCALE), GaussianMixture(torch.zeros(1), LOC[None], torch.eye(2)[None])):
        with pytest.raises(ValueError, match="independent prior on a box"):
            ProbitTransform(refused)


def test_mixtures_give_their_gaussian_factor_where_they_have_one_component():
    one = GaussianMixture(torch.zeros(1), torch.tensor([[0.5, 2.5]]), 0.1 * torch.eye(2)[None])
    two = GaussianMixture(torch.zeros(2), torch.tensor([[0.5, 2.5], [1.0, 2.2]]), 0.1 * torch.eye(2).repeat(2, 1, 1))
    mean, cov = one.gaussian_factor()
    torch.testing.assert_close(mean, one.means[0])
    torch.testing.assert_close(cov, one.covs[0])
    assert two.gaussian_factor() is NOT_GAUSSIAN
    truncated = TruncatedMixture(one, LOW, HIGH)
    torch.testing.assert_close(truncated.gaussian_factor()[1], one.covs[0])  # truncation only restricts the support
    assert one.as_gaussian_mixture() is one and truncated.as_gaussian_mixture() is None


def test_a_truncated_prior_restricts_its_own_prior_only_also_when_read_back_from_a_file(tmp_path):
    prior = BoxUniform(LOW, HIGH)
    posterior = TruncatedMixture(GaussianMixture(torch.zeros(1), torch.tensor([[5.0, 2.5]]), torch.eye(2)[None]),
                                 LOW, HIGH)
    proposal = TruncatedPrior(prior, posterior)
    assert proposal.restricts(prior) and not proposal.restricts(BoxUniform(LOW, 2 * HIGH))
    assert not posterior.restricts(prior)
    proposal.save(tmp_path / "proposal.pt")  # a resumed run reads the round's proposal from its artifact
    assert ParameterDistribution.load(tmp_path / "proposal.pt").restricts(prior)


def test_a_probit_posterior_gives_its_inner_distribution():
    transform = ProbitTransform(BoxUniform(LOW, HIGH))
    inner = GaussianMixture(torch.zeros(1), torch.zeros(1, 2), torch.eye(2)[None])
    assert ProbitPosterior(inner, transform).in_probit_space() is inner
    assert inner.in_probit_space() is None


def test_torch_distributions_are_converted_and_the_rest_refused():
    box = as_parameter_distribution(torch.distributions.Independent(torch.distributions.Uniform(LOW, HIGH), 1))
    assert isinstance(box, BoxUniform) and torch.equal(box.high, HIGH)
    gaussian = as_parameter_distribution(torch.distributions.Normal(LOC, SCALE))
    assert isinstance(gaussian, GaussianPrior) and gaussian.low is None
    ours = LogUniform(LOW, HIGH)
    assert as_parameter_distribution(ours) is ours and as_parameter_distribution(None) is None
    with pytest.raises(TypeError, match="proposal=.* is not supported"):
        as_parameter_distribution(torch.distributions.Exponential(torch.ones(2)), "proposal")
    assert math.isfinite(float(box.log_prob(_inside()).sum()))

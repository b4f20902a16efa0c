"""The Python API takes torch's independent priors (sbi's BoxUniform is an Independent(Uniform)) and refuses
any other prior at the call."""

import pytest
import torch

from bayessim_exp import api

LOW, HIGH = torch.tensor([0.5, -1.0]), torch.tensor([2.0, 1.0])


def simulations(n=2000, seed=0):
    """theta ~ U(box), x = theta + N(0, 0.05^2): the posterior sits around x."""
    g = torch.Generator().manual_seed(seed)
    theta = LOW + (HIGH - LOW) * torch.rand(n, 2, generator=g)
    return theta, theta + 0.05 * torch.randn(n, 2, generator=g)


@pytest.mark.parametrize("probit", [False, True], ids=["box", "probit"])
def test_fit_and_condition_with_a_torch_box_uniform(probit):
    torch.manual_seed(0)
    prior = torch.distributions.Independent(torch.distributions.Uniform(LOW, HIGH), 1)
    theta, x = simulations()
    fitted = api.fit_posterior_model("mdnn", theta, x, prior=prior, probit=probit, components=2, hidden=[32, 32],
                                     max_epochs=15, batch_size=128)
    assert isinstance(fitted.prior, api.BoxUniform) and torch.equal(fitted.prior.low, LOW.double())
    true = torch.tensor([1.2, 0.3])
    post = fitted.posterior(true + 0.05 * torch.randn(3, 2))  # three observations
    draws = post.sample((500,))
    assert draws.shape == (500, 2) and ((draws >= LOW) & (draws <= HIGH)).all()  # the prior's box
    log_prob = post.log_prob(torch.stack([true, torch.tensor([0.6, -0.9])]))
    assert torch.isfinite(log_prob).all() and log_prob[0] > log_prob[1] + 5  # the truth is far more likely
    assert (draws.mean(0) - true).abs().max() < 0.15


@pytest.mark.parametrize("prior, expected", [
    (torch.distributions.Independent(torch.distributions.Normal(torch.zeros(2), 2 * torch.ones(2)), 1),
     api.GaussianPrior),
    (torch.distributions.Normal(torch.zeros(2), 2 * torch.ones(2)), api.GaussianPrior),
    (torch.distributions.Uniform(LOW, HIGH), api.BoxUniform),
], ids=["Independent(Normal)", "Normal", "Uniform"])
def test_torch_independent_priors_become_ours(prior, expected):
    theta, x = simulations(200)
    converted = api.fit_posterior_model("linear", theta, x, prior=prior).prior
    assert type(converted) is expected
    if expected is api.BoxUniform:
        assert torch.equal(converted.low, LOW.double()) and torch.equal(converted.high, HIGH.double())
    else:  # untruncated, the same density
        normal = torch.distributions.Normal(torch.zeros(2, dtype=torch.float64), 2.0)
        assert converted.low is None
        assert torch.allclose(converted.log_prob(theta), normal.log_prob(theta.double()).sum(-1))


@pytest.mark.parametrize("prior", [
    torch.distributions.MultivariateNormal(torch.zeros(2), torch.eye(2)),
    torch.distributions.Independent(torch.distributions.Beta(torch.ones(2), torch.ones(2)), 1),
    torch.distributions.Uniform(torch.zeros(3, 2), torch.ones(3, 2)),  # a batch of boxes, not one prior
], ids=["MultivariateNormal", "Independent(Beta)", "batch of Uniforms"])
def test_any_other_prior_is_refused_at_the_call(prior):
    theta, x = simulations(200)
    with pytest.raises(TypeError, match="api.BoxUniform, api.GaussianPrior or api.LogUniform.*Independent"):
        api.fit_posterior_model("linear", theta, x, prior=prior)


def test_a_prior_over_other_parameters_is_refused():
    theta, x = simulations(200)
    with pytest.raises(ValueError, match="over 3 parameters, theta has 2"):
        api.fit_posterior_model("linear", theta, x, prior=api.BoxUniform(torch.zeros(3), torch.ones(3)))

"""Probit space against known answers: the prior is N(0, I) there, densities map back exactly,
and conditioning a linear-Gaussian model there matches the closed-form posterior in u."""

import math

import pytest
import torch
from linear_gaussian import LinearGaussian

from bayessim_exp import api
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior, LogUniform
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform, standard_normal_prior
from bayessim_exp.inference.bayessim.condition import condition

LOW, HIGH = torch.tensor([0.1, 1.0, -2.0], dtype=torch.float64), torch.tensor([5.0, 3.0, 4.0], dtype=torch.float64)
PRIORS = {
    "uniform": BoxUniform(LOW, HIGH),
    "loguniform": LogUniform(LOW[:2], HIGH[:2]),
    "gaussian": GaussianPrior(torch.tensor([1.0, 2.5, 0.0]), torch.tensor([2.0, 0.5, 1.0]), LOW, HIGH),
}


@pytest.mark.parametrize("name", PRIORS)
def test_prior_draws_are_standard_normal_in_probit_space(name):
    prior = PRIORS[name]
    torch.manual_seed(0)
    theta = prior.sample((20000,)).double()
    u = ProbitTransform(prior).to_probit(theta)
    assert u.mean(0).abs().max() < 0.03
    assert (u.std(0) - 1).abs().max() < 0.03
    assert torch.allclose(ProbitTransform(prior).from_probit(u), theta, atol=1e-9)


@pytest.mark.parametrize("name", PRIORS)
def test_standard_normal_maps_back_to_the_prior_density(name):
    prior = PRIORS[name]
    transform = ProbitTransform(prior)
    back = ProbitPosterior(standard_normal_prior(transform.dim), transform)
    torch.manual_seed(1)
    theta = prior.sample((500,)).double()
    assert torch.allclose(back.log_prob(theta), prior.log_prob(theta).double(), atol=1e-9)
    outside = theta[:1].clone()
    outside[0, 0] = transform.high[0] + 1
    assert back.log_prob(outside)[0] == -math.inf


def test_a_posterior_mapped_back_is_normalised_on_the_box():
    prior = BoxUniform(LOW[:1], HIGH[:1])
    inner = GaussianMixture(torch.zeros(2), torch.tensor([[-1.0], [1.5]]), torch.tensor([[[0.3]], [[0.05]]]))
    post = ProbitPosterior(inner, ProbitTransform(prior))
    grid = torch.linspace(float(LOW[0]), float(HIGH[0]), 200_001, dtype=torch.float64)[1:-1, None]
    mass = torch.trapezoid(post.log_prob(grid).exp(), grid[:, 0])
    assert abs(float(mass) - 1) < 1e-4
    draws = post.sample((50_000,))
    assert ((draws >= LOW[0]) & (draws <= HIGH[0])).all()
    # the mean of draws matches the density's mean
    mean = torch.trapezoid(grid[:, 0] * post.log_prob(grid).exp(), grid[:, 0])
    assert abs(float(draws.mean()) - float(mean)) < 0.02


def test_probit_conditioning_of_a_linear_gaussian_model_matches_the_closed_form():
    """x = A u + b + noise with u the probit of theta: the linear model recovers A, and the posterior in u
    given two observations is the Gaussian posterior under the N(0, I) prior."""
    torch.set_num_threads(1)
    prior = BoxUniform(LOW[:2], HIGH[:2])
    transform = ProbitTransform(prior)
    sim = LinearGaussian(torch.tensor([[1.0, 0.5], [-0.3, 2.0], [0.7, 0.0]]), torch.tensor([0.1, -0.2, 0.3]),
                         0.2 * torch.eye(3))
    torch.manual_seed(2)
    theta = prior.sample((20000,)).double()
    x = sim.simulate(transform.to_probit(theta), seed=3)
    fitted = api.fit_posterior_model("linear", theta, x, prior=prior, probit=True)
    u_true = torch.tensor([[0.5, -1.0]], dtype=torch.float64)
    xs = sim.simulate(u_true.expand(2, 2), seed=4)
    post = fitted.posterior(xs)
    mean, cov = sim.posterior(torch.zeros(2), torch.eye(2), xs)
    assert torch.allclose(post.inner.mean, mean, atol=0.03)
    assert torch.allclose(post.inner.covariance, cov, rtol=0.1, atol=2e-3)  # held-out residuals: 2000 draws
    theta_true = transform.from_probit(u_true)
    expected = torch.distributions.MultivariateNormal(mean, cov).log_prob(u_true) + transform.log_abs_det_jacobian(theta_true)
    assert torch.allclose(post.log_prob(theta_true), expected, atol=0.05)


def test_probit_conditioning_refuses_a_proposal_in_parameter_units():
    prior = BoxUniform(LOW[:2], HIGH[:2])
    fitted = api.fit_posterior_model("linear", prior.sample((200,)), torch.randn(200, 3), prior=prior, probit=True)
    proposal = GaussianPrior(torch.tensor([1.0, 2.0]), torch.tensor([1.0, 1.0]), LOW[:2], HIGH[:2])
    with pytest.raises(ValueError, match="probit-space model cannot correct"):
        condition(fitted.model, torch.randn(3), prior, proposal=proposal, probit=fitted.probit)


def test_snpe_a_in_probit_space_matches_the_closed_form():
    """Round 2 of SNPE-A where the default puts it, in probit space: parameters drawn from a Gaussian proposal
    in u (a previous posterior mapped back), x = A u + b + noise; the linear model fitted to those draws is
    the proposal posterior, and conditioning with the proposal's correction gives the closed-form posterior
    under the N(0, I) prior, for one and for two observations."""
    torch.set_num_threads(1)
    prior = BoxUniform(LOW[:2], HIGH[:2])
    transform = ProbitTransform(prior)
    sim = LinearGaussian(torch.tensor([[1.0, 0.5], [-0.3, 2.0], [0.7, 0.0]]), torch.tensor([0.1, -0.2, 0.3]),
                         0.2 * torch.eye(3))
    proposal_u = GaussianMixture(torch.zeros(1), torch.tensor([[0.4, -0.8]]), torch.tensor([[[0.3, 0.05], [0.05, 0.2]]]))
    proposal = ProbitPosterior(proposal_u, transform)
    torch.manual_seed(5)
    theta = proposal.sample((100_000,))
    fitted = api.fit_posterior_model("linear", theta, sim.simulate(transform.to_probit(theta), seed=6), prior=prior,
                                     probit=True)
    u_true = torch.tensor([[0.5, -1.0]], dtype=torch.float64)
    for n in (1, 2):
        xs = sim.simulate(u_true.expand(n, 2), seed=7 + n)
        post = fitted.posterior(xs, proposal=proposal)
        mean, cov = sim.posterior(torch.zeros(2), torch.eye(2), xs)
        assert isinstance(post.inner, GaussianMixture) and post.inner.num_components == 1
        assert torch.allclose(post.inner.mean, mean, atol=0.02), (n, post.inner.mean, mean)
        assert torch.allclose(post.inner.covariance, cov, rtol=0.08, atol=2e-3), (n, post.inner.covariance, cov)


def test_components_wider_than_the_prior_are_narrowed_to_it_keeping_the_closed_form():
    """Two observations in probit space divide by the N(0, I) prior once: conditionals of variance 2.5 along a
    direction (a fitting artefact: no posterior of a Gaussian prior is wider than it) would leave a negative
    precision; narrowed to the prior there, the product stays a Gaussian, equal to the narrowed product."""
    from bayessim_exp.inference.bayessim.correction import loewner_min, posterior

    wide = torch.tensor([[[2.5, 0.0], [0.0, 0.04]]], dtype=torch.float64)
    q = [GaussianMixture(torch.zeros(1), torch.tensor([[m, 0.3]]), wide) for m in (0.2, -0.1)]
    post = posterior(q, standard_normal_prior(2))
    assert isinstance(post, GaussianMixture)
    narrowed = loewner_min(wide, torch.eye(2, dtype=torch.float64))[0]
    assert torch.allclose(narrowed, torch.diag(torch.tensor([1.0, 0.04], dtype=torch.float64)))
    # N(m1, S) N(m2, S) / N(0, I) with S = diag(1, 0.04): precision 2 S^-1 - I
    precision = 2 * torch.linalg.inv(narrowed) - torch.eye(2, dtype=torch.float64)
    mean = torch.linalg.solve(precision, torch.linalg.inv(narrowed) @ torch.tensor([0.1, 0.6], dtype=torch.float64))
    assert torch.allclose(post.covariance, torch.linalg.inv(precision), atol=1e-9)
    assert torch.allclose(post.mean, mean, atol=1e-9)


def test_a_product_double_precision_cannot_hold_falls_back_to_the_narrowed_conditionals():
    """Far outside its training summaries a density model can return components of variance 4e14 beside a
    near-degenerate one (a pendulum logged 0.3 rad off, round 2): their product's covariance does not
    factorise even with jitter. The posterior then takes the conditionals narrowed to the prior, as for any
    component wider than it, instead of stopping the run."""
    from bayessim_exp.distributions.mixture import NotPositiveDefinite
    from bayessim_exp.inference.bayessim.correction import loewner_min, posterior

    # that run's two components, to the digits their product needs to fail (with 8 it factorises)
    flat = GaussianMixture(torch.zeros(1), torch.tensor([[-12.93, 0.99]]), torch.tensor(
        [[[425606165200000.0, -133194096100.0], [-133194096100.0, 41683294.78]]], dtype=torch.float64))
    sharp = GaussianMixture(torch.zeros(1), torch.tensor([[-17.35, -1.58]]), torch.tensor(
        [[[8.666749547e-10, -5.4803049e-06], [-5.4803049e-06, 0.03768767154]]], dtype=torch.float64))
    with pytest.raises(NotPositiveDefinite):
        flat.product(sharp)
    eye = torch.eye(2, dtype=torch.float64)
    narrowed = [GaussianMixture(q.log_weights, q.means, loewner_min(q.covs, eye)) for q in (flat, sharp)]
    post, expected = posterior([flat, sharp], standard_normal_prior(2)), posterior(narrowed, standard_normal_prior(2))
    assert isinstance(post, GaussianMixture)
    assert torch.allclose(post.mean, expected.mean) and torch.allclose(post.covariance, expected.covariance)


def test_conditionals_no_product_of_which_factorises_are_importance_sampled_from_side_by_side(monkeypatch):
    """Where neither the conditionals' product nor that of the conditionals narrowed to the prior factorises (a
    FrankaCabinet run's product temperature search, round 3, with policy.action_noise=0.1), the importance sampler
    draws from the conditionals side by side instead of from their product, and the run goes on."""
    from bayessim_exp.distributions.importance import ImportancePosterior
    from bayessim_exp.distributions.mixture import NotPositiveDefinite
    from bayessim_exp.inference.bayessim import correction

    eye = torch.eye(2, dtype=torch.float64)
    conditionals = [GaussianMixture(torch.zeros(1), torch.tensor([[0.5, 0.0]]), 0.3 * eye[None]),
                    GaussianMixture(torch.zeros(1), torch.tensor([[0.3, 0.2]]), 0.4 * eye[None])]
    expected = correction.posterior(conditionals, standard_normal_prior(2))
    assert isinstance(expected, GaussianMixture)

    def cannot_factorise(mixtures, max_components):
        raise NotPositiveDefinite("as double precision cannot")

    monkeypatch.setattr(correction, "_product", cannot_factorise)
    monkeypatch.setattr(correction, "_no_wider_than", lambda mix, cov0: cannot_factorise([mix], 1))
    post = correction.posterior(conditionals, standard_normal_prior(2), seed=0)
    assert isinstance(post, ImportancePosterior)
    draws = post.sample((20000,), generator=torch.Generator().manual_seed(1)).double()
    assert torch.allclose(draws.mean(0), expected.mean, atol=0.03)
    assert torch.allclose(torch.cov(draws.T), expected.covariance, atol=0.03)


def test_the_truths_place_is_scored_in_both_spaces_each_against_its_known_answer():
    """u ~ N(-2, 0.6^2) mapped onto a uniform box, the truth at u* = -1 (z = 1.67): in probit space its HPD level
    is P(|Z| < 1.67) = 0.904; in parameter space the Jacobian 1 / phi(u) moves the density's peak to u = -3.125
    (towards the face), so the region holding u* is [-5.25, -1]: 0.952. The spaces differ by 0.048, six times a
    level's standard error over 4,000 draws."""
    from scipy.stats import norm

    from bayessim_exp.diagnostics.scoring import truth_rank

    transform = ProbitTransform(BoxUniform(torch.tensor([0.0], dtype=torch.float64),
                                           torch.tensor([1.0], dtype=torch.float64)))
    inner = GaussianPrior(torch.tensor([-2.0], dtype=torch.float64), torch.tensor([0.6], dtype=torch.float64))
    posterior = ProbitPosterior(inner, transform)
    truth = transform.from_probit(torch.tensor([[-1.0]], dtype=torch.float64))[0].numpy()
    probit_level = 2 * norm.cdf(1 / 0.6) - 1
    parameter_level = norm.cdf(1 / 0.6) - norm.cdf(-3.25 / 0.6)
    levels = [truth_rank(posterior, ["x"], truth, seed) for seed in range(5)]
    assert abs(sum(r["hpd_level_probit"] for r in levels) / 5 - probit_level) < 0.01, levels
    assert abs(sum(r["hpd_level"] for r in levels) / 5 - parameter_level) < 0.01, levels
    assert truth_rank(BoxUniform(torch.zeros(1), torch.ones(1)), ["x"], truth, 0)["hpd_level_probit"] is None

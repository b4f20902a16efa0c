"""The truncated proposal against brute force: its draws are the prior's draws that fall in the region and its mass
is their share of the prior, for posteriors in probit space (relaxed_cover.py), in the box (a box around the region
holds every point of it) and without a mixture form (the whole prior); in 30 parameters against an exact
reference."""

import copy
import math

import pytest
import torch

from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior, LogUniform
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
from bayessim_exp.distributions.restricted import Restricted
from bayessim_exp.distributions.truncated_prior import TruncatedPrior

LOW, HIGH = torch.tensor([0.5, 0.1], dtype=torch.float64), torch.tensor([2.0, 0.9], dtype=torch.float64)
PRIORS = {
    "uniform": BoxUniform(LOW, HIGH),
    "loguniform": LogUniform(LOW, HIGH),
    "gaussian": GaussianPrior(torch.tensor([1.0, 0.5]), torch.tensor([0.5, 0.3]), LOW, HIGH),
}


def _narrow_mixture() -> GaussianMixture:
    covs = torch.tensor([[[0.004, 0.001], [0.001, 0.002]], [[0.001, 0.0], [0.0, 0.003]], [[0.002, -0.001], [-0.001, 0.002]]])
    return GaussianMixture(torch.tensor([0.0, -0.5, 0.3]), torch.tensor([[0.1, 0.0], [0.2, 0.05], [0.05, -0.1]]),
                           covs)


def test_the_superlevel_box_holds_every_point_of_the_set():
    mix = _narrow_mixture()
    grid = torch.stack(torch.meshgrid(*[torch.linspace(-1, 1, 801, dtype=torch.float64)] * 2, indexing="ij"), -1).reshape(-1, 2)
    value = mix.log_prob(grid)
    level = float(torch.quantile(value, 0.99))
    low, high = mix.superlevel_box(level)
    above = grid[value >= level]
    assert ((above >= low) & (above <= high)).all()
    # not the whole grid: the box is informative
    assert ((high - low) < 1.0).all()


def _posteriors(prior):
    transform = ProbitTransform(copy.deepcopy(prior))  # as loaded from a run directory: an equal prior, not the same
    probit = ProbitPosterior(_narrow_mixture(), transform)
    # the same shape in parameter units, truncated to the box (method.parameter_space=box)
    centre = 0.5 * (transform.low + transform.high)
    box = TruncatedMixture(_narrow_mixture().affine(centre, 0.3 * (transform.high - transform.low)),
                           transform.low, transform.high)
    return {"probit": probit, "box": box}


@pytest.mark.parametrize("prior_name", PRIORS)
@pytest.mark.parametrize("space", ["probit", "box"])
def test_draws_and_mass_match_rejection_from_the_whole_prior(prior_name, space):
    prior = PRIORS[prior_name]
    posterior = _posteriors(prior)[space]
    proposal = TruncatedPrior(prior, posterior, seed=3)
    reference = prior.sample((2_000_000,), generator=torch.Generator().manual_seed(7)).double()
    inside = proposal._in_region(reference)
    mass = inside.double().mean().item()
    assert mass < 0.1 and proposal.acceptance > 3 * mass  # the box spares most of the prior's rejections
    assert abs(proposal.mass / mass - 1) < 0.05  # the estimate's relative error is ~1 % at acceptance 0.3
    draws = proposal.sample((20_000,), generator=torch.Generator().manual_seed(0))
    assert proposal._in_region(draws).all()
    expected = reference[inside]
    se = expected.std(0) / math.sqrt(len(draws))
    assert ((draws.mean(0) - expected.mean(0)).abs() < 5 * se).all()
    assert ((draws.std(0) / expected.std(0) - 1).abs() < 0.03).all()
    lp = proposal.log_prob(draws[:100])
    torch.testing.assert_close(lp, prior.log_prob(draws[:100]).double() - math.log(proposal.mass))


def _wide_in_one_direction() -> GaussianMixture:
    """Wider than the prior (N(0, I) in probit space) along the second axis: its region is unbounded there."""
    return GaussianMixture(torch.zeros(1), torch.tensor([[0.4, 0.0]]), torch.diag(torch.tensor([0.02, 1.5]))[None])


@pytest.mark.parametrize("prior_name", PRIORS)
def test_a_component_wider_than_the_prior_still_gives_exact_draws_and_mass(prior_name):
    prior = PRIORS[prior_name]
    proposal = TruncatedPrior(prior, ProbitPosterior(_wide_in_one_direction(), ProbitTransform(prior)), seed=1)
    reference = prior.sample((1_000_000,), generator=torch.Generator().manual_seed(7)).double()
    inside = proposal._in_region(reference)
    assert abs(proposal.mass / inside.double().mean().item() - 1) < 0.05
    draws = proposal.sample((20_000,), generator=torch.Generator().manual_seed(0))
    expected = reference[inside]
    assert ((draws.mean(0) - expected.mean(0)).abs() < 5 * expected.std(0) / math.sqrt(len(draws))).all()
    assert ((draws.std(0) / expected.std(0) - 1).abs() < 0.03).all()


def _uniform_in_ellipsoid(centre, chol_a, radius_sq, n, generator):
    """n uniform draws in {(u - centre)^T A (u - centre) <= radius_sq}, A = chol_a chol_a^T, and the ellipsoid's
    log volume."""
    d = len(centre)
    z = torch.randn(n, d, dtype=torch.float64, generator=generator)
    r = torch.rand(n, 1, dtype=torch.float64, generator=generator) ** (1 / d) * math.sqrt(radius_sq)
    y = z / z.norm(dim=1, keepdim=True) * r
    log_volume = (0.5 * d * math.log(math.pi) - math.lgamma(d / 2 + 1) + 0.5 * d * math.log(radius_sq)
                  - torch.log(torch.diagonal(chol_a)).sum())
    return centre + torch.linalg.solve_triangular(chol_a.T, y.T, upper=True).T, float(log_volume)


def test_thirty_parameters_and_a_narrow_posterior_are_sampled_exactly():
    # a posterior 1/20 of the prior's width in probit space, around a point in the prior's joint tail (every
    # multiplier of a [0.1, 10] range near 1, ShadowHand's masses): its region holds ~1e-40 of the prior, so
    # neither the prior nor a box around the region (~1e-13 of it inside) gives candidates; the tilted prior does
    d = 30
    prior = BoxUniform(torch.full((d,), 0.1, dtype=torch.float64), torch.full((d,), 10.0, dtype=torch.float64))
    transform = ProbitTransform(prior)
    rotation, _ = torch.linalg.qr(torch.randn(d, d, dtype=torch.float64, generator=torch.Generator().manual_seed(0)))
    cov = rotation @ torch.diag(torch.linspace(0.03, 0.08, d, dtype=torch.float64) ** 2) @ rotation.T
    mean = torch.full((1, d), -1.3, dtype=torch.float64)
    proposal = TruncatedPrior(prior, ProbitPosterior(GaussianMixture(torch.zeros(1), mean, cov[None]), transform),
                              seed=2)
    assert proposal.acceptance > 0.05
    draws = proposal.sample((20_000,), generator=torch.Generator().manual_seed(3))
    assert proposal._in_region(draws.float().double()).all()  # as the pipeline stores them: the proposal holds them
    # the region in probit space is the ellipsoid (u - c)^T A (u - c) <= r^2, A = P - I (uniform prior): the
    # reference is uniform draws in it weighted by the prior N(u; 0, I)
    precision = torch.linalg.inv(cov)
    a = precision - torch.eye(d, dtype=torch.float64)
    centre = torch.linalg.solve(a, precision @ mean[0])
    u = transform.to_probit(draws)
    radius_sq = float((((u - centre) @ a) * (u - centre)).sum(-1).max())
    chol_a = torch.linalg.cholesky(a)
    uniform, log_volume = _uniform_in_ellipsoid(centre, chol_a, radius_sq, 400_000, torch.Generator().manual_seed(4))
    log_w = -0.5 * (uniform**2).sum(-1) - 0.5 * d * math.log(2 * math.pi)
    assert abs(proposal.log_mass - (log_volume + float(torch.logsumexp(log_w, 0)) - math.log(len(uniform)))) < 0.05
    w = torch.softmax(log_w, 0)

    def rim(points):  # squared radius in the metric of A, relative to the rim: uniform draws pile up near 1
        return (((points - centre) @ a) * (points - centre)).sum(-1) / radius_sq

    for statistic in (rim, lambda points: points @ rotation[:, 0], lambda points: points @ rotation[:, -1]):
        mean_ref = float((w * statistic(uniform)).sum())
        sd_ref = float((w * (statistic(uniform) - mean_ref) ** 2).sum().sqrt())
        assert abs(float(statistic(u).mean()) - mean_ref) < 5 * sd_ref / math.sqrt(len(u))


def test_a_posterior_without_a_mixture_form_draws_from_the_whole_prior():
    prior = PRIORS["uniform"]
    flow_like = Restricted(torch.distributions.MultivariateNormal(torch.tensor([1.0, 0.5], dtype=torch.float64),
                                                                  0.05 * torch.eye(2, dtype=torch.float64)),
                           prior.low, prior.high)
    proposal = TruncatedPrior(prior, flow_like, hpd_mass=0.9, seed=0)
    assert proposal.acceptance == pytest.approx(proposal.mass)


def test_a_region_too_small_for_the_candidates_is_refused():
    prior = PRIORS["uniform"]
    tiny = Restricted(torch.distributions.MultivariateNormal(torch.tensor([1.0, 0.5], dtype=torch.float64),
                                                             torch.diag(torch.tensor([1e-8, 1e-3], dtype=torch.float64))),
                      prior.low, prior.high)
    with pytest.raises(ValueError, match="too little to sample"):
        TruncatedPrior(prior, tiny, seed=0)


def test_draws_stay_in_the_region_once_stored_in_float32():
    """A region reaching the box's face (a read of the real data beyond the prior's range, method.escape=linear):
    parameters within 1e-8 of the face round to it in float32, where the pipeline stores them, and their probit
    coordinate jumps; the proposal must still hold every stored draw, or its density there is zero."""
    prior = PRIORS["uniform"]
    at_face = GaussianMixture(torch.zeros(1), torch.tensor([[-7.0, 0.0]]), torch.diag(torch.tensor([0.25, 0.04]))[None])
    proposal = TruncatedPrior(prior, ProbitPosterior(at_face, ProbitTransform(prior)), seed=0)
    stored = proposal.sample((20_000,), generator=torch.Generator().manual_seed(1)).float().double()
    assert torch.isfinite(proposal.log_prob(stored)).all()


@pytest.mark.parametrize("prior_name", PRIORS)
def test_a_diagonal_mixture_s_draws_and_mass_match_rejection_from_the_whole_prior(prior_name):
    # a diagonal model's posterior (relaxed_cover.py's elementwise path), several components of different weights
    prior = PRIORS[prior_name]
    mixture = GaussianMixture(torch.tensor([0.0, -0.7, 0.4]), torch.tensor([[0.1, 0.0], [0.3, 0.1], [0.0, -0.15]]),
                              torch.diag_embed(torch.tensor([[0.004, 0.002], [0.001, 0.003], [0.002, 0.005]])))
    proposal = TruncatedPrior(prior, ProbitPosterior(mixture, ProbitTransform(prior)), seed=1)
    reference = prior.sample((2_000_000,), generator=torch.Generator().manual_seed(7)).double()
    inside = proposal._in_region(reference)
    assert abs(proposal.mass / inside.double().mean().item() - 1) < 0.05
    draws = proposal.sample((20_000,), generator=torch.Generator().manual_seed(0))
    assert proposal._in_region(draws).all()
    expected = reference[inside]
    assert ((draws.mean(0) - expected.mean(0)).abs() < 5 * expected.std(0) / math.sqrt(len(draws))).all()
    assert ((draws.std(0) / expected.std(0) - 1).abs() < 0.03).all()

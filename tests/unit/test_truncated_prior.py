"""The truncated proposal against brute force: its region's box holds every point of the region, its
draws are the prior's draws that fall in the region, and its mass is their share of the prior."""

import copy
import math

import pytest
import torch

from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior, LogUniform
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
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


@pytest.mark.parametrize("over_standard_normal", [False, True])
def test_the_superlevel_box_holds_every_point_of_the_set(over_standard_normal):
    mix = _narrow_mixture()
    grid = torch.stack(torch.meshgrid(*[torch.linspace(-1, 1, 801, dtype=torch.float64)] * 2, indexing="ij"), -1).reshape(-1, 2)
    value = mix.log_prob(grid) - (torch.distributions.Normal(0.0, 1.0).log_prob(grid).sum(-1) if over_standard_normal else 0)
    level = float(torch.quantile(value, 0.99))
    low, high = mix.superlevel_box(level, over_standard_normal)
    above = grid[value >= level]
    assert ((above >= low) & (above <= high)).all()
    # not the whole grid: the box is informative
    assert ((high - low) < 1.0).all()


def test_a_component_wider_than_the_reference_gives_no_box():
    wide = GaussianMixture(torch.zeros(1), torch.zeros(1, 2), torch.diag(torch.tensor([0.1, 1.5]))[None])
    assert wide.superlevel_box(-1.0, over_standard_normal=True) is None
    assert wide.superlevel_box(-1.0) is not None  # over a flat reference every Gaussian is bounded


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


def test_without_a_box_the_candidates_are_the_whole_prior():
    prior = PRIORS["uniform"]
    wide = GaussianMixture(torch.zeros(1), torch.zeros(1, 2), torch.diag(torch.tensor([0.3, 1.5]))[None])
    proposal = TruncatedPrior(prior, ProbitPosterior(wide, ProbitTransform(prior)), hpd_mass=0.9, seed=0)
    assert proposal.acceptance == pytest.approx(proposal.mass)


def test_a_region_too_small_for_the_candidates_is_refused():
    prior = PRIORS["uniform"]
    tiny = GaussianMixture(torch.zeros(1), torch.zeros(1, 2), torch.diag(torch.tensor([1e-8, 1.5]))[None])
    with pytest.raises(ValueError, match="too little to sample"):
        TruncatedPrior(prior, ProbitPosterior(tiny, ProbitTransform(prior)), seed=0)

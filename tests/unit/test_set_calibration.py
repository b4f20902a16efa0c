"""The product's temperature fitted on simulated sets: about 1 where the per-trajectory posteriors are exact,
below 1 where they are too narrow, against a linear-Gaussian model whose posteriors are known."""

import pytest
import torch

from bayessim_exp.distributions.hpd import hpd_level
from bayessim_exp.distributions.independent import GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.inference.bayessim.correction import posterior
from bayessim_exp.inference.bayessim.set_calibration import miscalibration, product_temperature

NOISE = 0.5  # x = theta + N(0, NOISE^2) in one dimension, theta ~ N(0, 1)
PRIOR = GaussianPrior(torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.float64))


def _sets(count: int, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    theta = torch.randn(count, 1, dtype=torch.float64, generator=g)
    return theta, theta[:, None] + NOISE * torch.randn(count, n, 1, dtype=torch.float64, generator=g)


def _single(x: torch.Tensor, squeeze: float) -> GaussianMixture:
    """The posterior given one x (variance NOISE^2 / (1 + NOISE^2)), its variance multiplied by `squeeze`."""
    var = NOISE**2 / (1 + NOISE**2)
    return GaussianMixture(torch.zeros(1), (x / (1 + NOISE**2))[None], squeeze * var * torch.ones(1, 1, 1))


def _fitted(squeeze: float, n: int = 3) -> float:
    theta, x = _sets(400, n, seed=0)

    def levels_at(tau: float) -> torch.Tensor:
        g = torch.Generator().manual_seed(1)
        levels = []
        for xs, t in zip(x, theta):
            post = posterior([_single(xi, squeeze) for xi in xs], PRIOR, temperature=tau)
            levels.append(hpd_level(post, t[None], post.sample((500,), generator=g).double(), g))
        return torch.tensor(levels)

    return product_temperature(levels_at, (0.5, 0.9))[0]


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_exact_per_trajectory_posteriors_keep_about_the_plain_product():
    """400 sets: a share's standard error is 0.025 at 50 %, so the fitted tau stays within an eighth of a doubling."""
    assert _fitted(squeeze=1.0) >= 2 ** (-1 / 8)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_per_trajectory_posteriors_too_narrow_widen_the_product_to_the_calibrated_temperature():
    """Variances at a third of the exact ones (precision 15 instead of 5): each q_i / p has precision 14 and mean
    (12/14) x_i, so the tempered posterior of three has precision 1 + 42 tau and mean c xbar, c = 36 tau / (1 + 42
    tau). Its error theta - c xbar has variance (1 - c)^2 + c^2 / 12 (xbar's noise NOISE^2 / 3); calibrated where
    that equals the posterior's 1 / (1 + 42 tau): tau = 0.21 (0.286 would only fix the precision). 400 sets: within
    a quarter of a doubling."""
    tau = _fitted(squeeze=1 / 3)
    assert 2 ** (-2.5) <= tau <= 2 ** (-2.0), tau


def test_miscalibration_counts_each_level_in_its_standard_errors():
    levels = torch.tensor([0.1, 0.3, 0.6, 0.95])  # shares inside: 0.5 at 50 %, 0.75 at 90 %
    assert miscalibration(levels, (0.5,)) == 0.0
    assert miscalibration(levels, (0.9,)) == pytest.approx(0.15**2 / (0.9 * 0.1 / 4))


def test_the_record_holds_each_temperature_tried_and_ties_go_to_the_narrower():
    def levels_at(tau: float) -> torch.Tensor:  # calibrated at every tau <= 0.5
        return torch.tensor([0.25, 0.75]) if tau <= 0.5 else torch.tensor([0.95, 0.95])

    tau, record = product_temperature(levels_at, (0.5,))
    assert tau == 0.5 and record["sets"] == 2 and record["inside"]["0.5"] == {"0.5": 0.5}
    assert record["inside"]["1"] == {"0.5": 0.0}
    assert len(record["inside"]) == 5 + 6  # the coarse grid down to two steps past 0.5, then eighths on both sides


def _mixture_near(g: torch.Generator, u: torch.Tensor, components: int, wide: bool,
                  diagonal: bool = False) -> GaussianMixture:
    """Components of random orientation (or on the axes: `diagonal`, a diagonal model's) around u [D]; `wide`: the
    first one wider than the N(0, I) prior along one axis."""
    dim = len(u)
    a = torch.randn(components, dim, dim, dtype=torch.float64, generator=g)
    covs = 0.1 * a @ a.transpose(-1, -2) + 0.05 * torch.eye(dim, dtype=torch.float64)
    if diagonal:
        covs = torch.diag_embed(torch.diagonal(covs, dim1=-2, dim2=-1))
    if wide:
        covs[0, 0, 0] += 2.5
    means = u + 0.3 * torch.randn(components, dim, dtype=torch.float64, generator=g)
    return GaussianMixture(torch.randn(components, generator=g), means, covs)


@pytest.mark.parametrize("covariance", ["full", "diagonal"])
@pytest.mark.parametrize("space", ["probit", "gaussian prior, corrected proposal"])
def test_the_sets_read_together_give_each_set_its_own_level_as_set_by_set(space, covariance, caplog):
    """condition.tempered_products' MixtureStack read by own_levels: the levels of the loop over each set's
    tempered_product and own_level, from the same random stream, to rounding. Some sets' plain products have no
    closed form at some temperatures (every trajectory's first component wider than the prior along one axis: their
    precisions there sum to less than the 3 tau - 1 that dividing by the prior takes away), so the stack mixes
    narrowed and plain products; three trajectories of two components: products of eight."""
    from bayessim_exp.distributions.hpd import own_level, own_levels
    from bayessim_exp.distributions.independent import BoxUniform
    from bayessim_exp.distributions.mixture_stack import MixtureStack
    from bayessim_exp.distributions.probit import ProbitTransform
    from bayessim_exp.inference.bayessim.condition import tempered_product, tempered_products

    g = torch.Generator().manual_seed(3)
    dim, sets, n = 3, 12, 3
    if space == "probit":
        prior = BoxUniform(torch.zeros(dim), 2 * torch.ones(dim))
        probit, proposal = ProbitTransform(prior), None
        theta = prior.sample((sets,), generator=g)
        u = probit.to_probit(theta)
    else:
        prior, probit = GaussianPrior(torch.zeros(dim), torch.ones(dim)), None
        proposal = GaussianMixture(torch.zeros(1), 0.1 * torch.ones(1, dim), 0.8 * torch.eye(dim)[None])
        theta = u = torch.randn(sets, dim, dtype=torch.float64, generator=g)
    conditionals = [[_mixture_near(g, u[s], 2, wide=s % 3 == 0, diagonal=covariance == "diagonal") for _ in range(n)]
                    for s in range(sets)]
    together = tempered_products(conditionals, prior, 50, proposal, 0, probit)
    one_by_one = [tempered_product(c, prior, 50, proposal, 0, probit, warn=False) for c in conditionals]
    with caplog.at_level("INFO"):
        for tau in (1.0, 0.7, 0.3):
            stack = together(tau)
            assert isinstance(stack, MixtureStack) and len(stack) == sets
            assert (stack.diagonal_std is not None) == (covariance == "diagonal")
            read = own_levels(stack, theta, 200, torch.Generator().manual_seed(5))
            g_each = torch.Generator().manual_seed(5)
            each = torch.tensor([own_level(p(tau), t, 200, g_each) for p, t in zip(one_by_one, theta)],
                                dtype=torch.float64)
            torch.testing.assert_close(read, each, rtol=0, atol=1e-12)
            assert float(read.min()) < 0.5 and int((read < 1).sum()) > sets // 2  # levels that vary
    assert "narrowed" in caplog.text

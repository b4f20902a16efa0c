"""Gaussian-mixture algebra against closed forms; truncation to the prior box."""

import math

import pytest
import torch

from bayessim_exp.distributions.base import ParameterDistribution
from bayessim_exp.distributions.mixture import GaussianMixture, MixtureBatch, TruncatedMixture


def gaussian(mean, cov):
    return GaussianMixture(torch.zeros(1), torch.tensor([mean], dtype=torch.float64), torch.tensor([cov], dtype=torch.float64))


def test_product_of_two_gaussians_is_the_analytic_gaussian():
    A, B = torch.tensor([[1.0, 0.3], [0.3, 0.5]]), torch.tensor([[0.4, -0.1], [-0.1, 2.0]])
    a, b = torch.tensor([0.2, -1.0]), torch.tensor([1.0, 0.5])
    prod = gaussian(a.tolist(), A.tolist()).product(gaussian(b.tolist(), B.tolist()))
    C = torch.linalg.inv(torch.linalg.inv(A) + torch.linalg.inv(B))
    c = C @ (torch.linalg.solve(A, a) + torch.linalg.solve(B, b))
    torch.testing.assert_close(prod.mean.float(), c, atol=1e-6, rtol=0)
    torch.testing.assert_close(prod.covariance.float(), C, atol=1e-6, rtol=0)


def test_mixture_product_weights_follow_overlap():
    # two-component mixture times a narrow Gaussian at the second component: weight moves there
    mix = GaussianMixture(torch.zeros(2), torch.tensor([[-2.0], [2.0]]), torch.ones(2, 1, 1))
    prod = mix.product(gaussian([2.0], [[0.25]]))
    w = prod.log_weights.exp()
    expected = torch.tensor([math.exp(-0.5 * 16 / 1.25), 1.0], dtype=torch.float64)
    torch.testing.assert_close(w, expected / expected.sum(), atol=1e-9, rtol=0)


def _random_mixture(k: int, d: int, seed: int) -> GaussianMixture:
    g = torch.Generator().manual_seed(seed)
    factors = torch.randn(k, d, d, generator=g, dtype=torch.float64)
    covs = factors @ factors.transpose(-1, -2) / d + 0.1 * torch.eye(d, dtype=torch.float64)
    return GaussianMixture(torch.randn(k, generator=g), torch.randn(k, d, generator=g), covs)


def test_product_kept_to_its_heaviest_components_is_the_pruned_full_product():
    a, b = _random_mixture(6, 4, 0), _random_mixture(5, 4, 1)
    full, kept = a.product(b).prune(7), a.product(b, max_components=7)
    assert kept.num_components == 7
    torch.testing.assert_close(kept.log_weights, full.log_weights, atol=1e-12, rtol=0)
    torch.testing.assert_close(kept.means, full.means, atol=1e-12, rtol=0)
    torch.testing.assert_close(kept.covs, full.covs, atol=1e-12, rtol=0)


def test_moments_and_sampling_agree():
    mix = GaussianMixture(torch.tensor([0.0, 1.0]), torch.tensor([[0.0, 0.0], [3.0, 1.0]]),
                          torch.stack([torch.eye(2), 0.5 * torch.eye(2)]))
    s = mix.sample((200_000,), generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(s.mean(0), mix.mean, atol=0.02, rtol=0)
    torch.testing.assert_close(torch.cov(s.T), mix.covariance, atol=0.03, rtol=0)


def test_truncation_keeps_samples_inside_and_renormalises():
    mix = GaussianMixture(torch.zeros(2), torch.tensor([[0.9, 0.0], [0.0, -0.8]]),
                          torch.stack([0.3 * torch.eye(2), torch.tensor([[0.5, 0.2], [0.2, 0.4]])]))
    low, high = torch.tensor([0.0, -1.0]), torch.tensor([1.0, 1.0])
    trunc = TruncatedMixture(mix, low, high)
    s = trunc.sample((50_000,))
    assert ((s >= low) & (s <= high)).all()
    # the density integrates to one over the box (midpoint rule on a fine grid)
    n = 400
    gx = low[0] + (torch.arange(n) + 0.5) * (high[0] - low[0]) / n
    gy = low[1] + (torch.arange(n) + 0.5) * (high[1] - low[1]) / n
    grid = torch.stack(torch.meshgrid(gx, gy, indexing="ij"), -1).reshape(-1, 2)
    integral = trunc.log_prob(grid).exp().sum() * ((high - low).prod() / n**2)
    assert integral.item() == pytest.approx(1.0, abs=0.01)
    assert trunc.log_prob(torch.tensor([[1.5, 0.0]])).item() == -math.inf
    # the truncated mean is the mean of the untruncated mixture restricted to the box
    raw = mix.sample((400_000,), generator=torch.Generator().manual_seed(1))
    inside = raw[((raw >= low) & (raw <= high)).all(1)]
    torch.testing.assert_close(trunc.mean, inside.mean(0), atol=0.01, rtol=0)


def test_save_and_load_round_trip(tmp_path):
    mix = GaussianMixture(torch.tensor([0.3, -0.2]), torch.randn(2, 3), torch.stack([torch.eye(3)] * 2))
    trunc = TruncatedMixture(mix, -torch.ones(3), torch.ones(3))
    trunc.save(tmp_path / "posterior.pt")
    back = ParameterDistribution.load(tmp_path / "posterior.pt")
    x = torch.rand(5, 3) * 2 - 1
    torch.testing.assert_close(back.log_prob(x), trunc.log_prob(x))


def test_covariance_left_indefinite_by_rounding_is_repaired_with_a_small_jitter(caplog):
    # rank-deficient by construction: cholesky fails without the jitter
    v = torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64)
    cov = (v.T @ v).unsqueeze(0)
    mix = GaussianMixture(torch.zeros(1), torch.zeros(1, 3), cov)
    assert "not positive definite by rounding" in caplog.text
    torch.testing.assert_close(mix.covs, cov, rtol=1e-3, atol=0)
    with pytest.raises(ValueError, match="not finite"):
        GaussianMixture(torch.zeros(1), torch.zeros(1, 3), torch.full((1, 3, 3), float("inf")))


def test_a_batch_of_mixtures_matches_its_rows_one_by_one():
    g = torch.Generator().manual_seed(0)
    n, k, d = 4, 3, 3
    factors = torch.triu(torch.randn(n, k, d, d, generator=g, dtype=torch.float64), 1) \
        + torch.diag_embed(torch.rand(n, k, d, generator=g, dtype=torch.float64) + 0.5)
    batch = MixtureBatch(torch.randn(n, k, generator=g), torch.randn(n, k, d, generator=g), factors)
    inverse = torch.linalg.inv(factors)
    rows = [GaussianMixture(batch.log_weights[i], batch.means[i], inverse[i] @ inverse[i].transpose(-1, -2)) for i in range(n)]
    theta = torch.randn(5, n, d, generator=g, dtype=torch.float64)
    expected = torch.stack([rows[i].log_prob(theta[:, i]) for i in range(n)], -1)
    torch.testing.assert_close(batch.log_prob(theta), expected)
    draws = batch.sample(40000, torch.Generator().manual_seed(1))
    for i in range(n):
        torch.testing.assert_close(draws[:, i].mean(0), rows[i].mean, atol=0.05, rtol=0)
        torch.testing.assert_close(torch.cov(draws[:, i].T), rows[i].covariance, atol=0.1, rtol=0.05)


def test_a_diagonal_mixture_s_density_is_the_multivariate_normals_near_its_components_and_far_from_them():
    # the diagonal path expands the quadratic form into matrix products: it must keep float64's accuracy where the
    # points sit on a narrow component (cancellation) and where they are far from all of them
    g = torch.Generator().manual_seed(0)
    d, k = 102, 50
    means = -1.3 + 0.1 * torch.randn(k, d, dtype=torch.float64, generator=g)
    std = torch.exp(torch.empty(k, d, dtype=torch.float64).uniform_(math.log(1e-3), math.log(2.0), generator=g))
    mix = GaussianMixture(torch.randn(k, generator=g), means, torch.diag_embed(std**2))
    points = torch.cat([means[:5] + 1e-3 * torch.randn(5, d, dtype=torch.float64, generator=g),
                        3 * torch.randn(5, d, dtype=torch.float64, generator=g)])
    reference = torch.stack([torch.distributions.MultivariateNormal(m, torch.diag(s**2)).log_prob(points)
                             for m, s in zip(means, std)], -1)
    assert mix.diagonal_std is not None  # the elementwise path
    torch.testing.assert_close(mix.component_log_prob(points), reference, rtol=1e-10, atol=1e-6)

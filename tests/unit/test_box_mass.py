"""The box mass of Gaussian mixture components (models/box_mass.py) against scipy, and the truncated batch."""

import math

import numpy as np
import pytest
import torch
from scipy.stats import multivariate_normal

from bayessim_exp.models.box_mass import TruncatedMixtureBatch, log_box_mass


def _factor(cov: list[list[float]]) -> torch.Tensor:
    """Upper-triangular U with U^T U the precision."""
    return torch.linalg.cholesky(torch.linalg.inv(torch.tensor(cov, dtype=torch.float64))).T


def _scipy_mass(mean, cov, low, high) -> float:
    dist = multivariate_normal(mean=mean, cov=cov)
    return dist.cdf(high) - dist.cdf([low[0], high[1]]) - dist.cdf([high[0], low[1]]) + dist.cdf(low)


@pytest.mark.parametrize("mean, cov", [([0.3, -0.2], [[0.5, 0.3], [0.3, 0.8]]),
                                       ([1.5, 0.9], [[4.0, -1.9], [-1.9, 1.0]]),
                                       ([2.5, -2.0], [[0.2, 0.05], [0.05, 0.3]])])
def test_full_two_dimensional_mass_matches_scipy(mean, cov):
    low, high = [-1.7, -1.7], [1.7, 1.7]
    got = log_box_mass(torch.tensor([[mean]], dtype=torch.float64), _factor(cov)[None, None],
                       torch.tensor(low), torch.tensor(high), diagonal=False)
    assert math.exp(float(got)) == pytest.approx(_scipy_mass(mean, cov, low, high), rel=1e-4, abs=1e-9)


def test_diagonal_mass_is_the_product_of_the_marginals():
    means = torch.tensor([[[0.5, -3.0, 1.0]]], dtype=torch.float64)
    sd = torch.tensor([0.7, 1.2, 0.1], dtype=torch.float64)
    low, high = torch.tensor([-1.0, -1.0, 0.0]), torch.tensor([1.0, 1.0, 1.05])
    got = log_box_mass(means, torch.diag(1 / sd)[None, None], low, high, diagonal=True)
    normal = torch.distributions.Normal(means[0, 0], sd)
    want = torch.log(normal.cdf(high.double()) - normal.cdf(low.double())).sum()
    assert float(got) == pytest.approx(float(want), rel=1e-9)


def test_truncated_batch_integrates_to_one_and_samples_inside():
    U = _factor([[1.0, 0.6], [0.6, 2.0]])
    batch = TruncatedMixtureBatch(torch.zeros(1, 1), torch.tensor([[[0.8, 0.2]]]), U[None, None],
                                  torch.tensor([0.0, -1.0]), torch.tensor([1.0, 1.0]), diagonal=False)
    grid = torch.stack(torch.meshgrid(torch.linspace(0.0025, 0.9975, 200), torch.linspace(-0.995, 0.995, 200),
                                      indexing="ij"), -1).reshape(-1, 1, 2)
    integral = float(batch.log_prob(grid.double()).exp().mean()) * 2.0  # the box's area
    assert integral == pytest.approx(1.0, abs=2e-3)
    draws = batch.sample(2000, torch.Generator().manual_seed(0))
    assert bool(((draws[..., 0] >= 0) & (draws[..., 0] <= 1) & (draws[..., 1].abs() <= 1)).all())
    assert not np.isfinite(float(batch.log_prob(torch.tensor([[[1.5, 0.0]]], dtype=torch.float64))))

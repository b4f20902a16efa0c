"""The product's temperature fitted on simulated sets: 1 where the per-trajectory posteriors are exact,
below 1 where they are too narrow, against a linear-Gaussian model whose posteriors are known."""

import torch

from bayessim_exp.distributions.independent import GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.inference.bayessim.correction import posterior
from bayessim_exp.inference.bayessim.set_calibration import product_temperature

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

    def log_density_at(tau: float) -> torch.Tensor:
        return torch.cat([posterior([_single(xi, squeeze) for xi in xs], PRIOR, temperature=tau).log_prob(t[None])
                          for xs, t in zip(x, theta)])

    return product_temperature(log_density_at)[0]


def test_exact_per_trajectory_posteriors_keep_the_plain_product():
    assert _fitted(squeeze=1.0) == 1.0


def test_per_trajectory_posteriors_too_narrow_widen_the_product():
    """Variances at a third of the exact ones: the product of three is about three times too narrow."""
    tau = _fitted(squeeze=1 / 3)
    assert 0.25 <= tau <= 0.5, tau


def test_the_record_holds_each_temperature_tried():
    tau, record = product_temperature(lambda t: torch.tensor([-abs(t - 0.5)], dtype=torch.float64))
    assert tau == 0.5 and record["sets"] == 1 and record["mean_log_density"]["0.5"] == 0.0
    assert len(record["mean_log_density"]) == 9

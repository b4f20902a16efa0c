"""SimOpt's discrepancy: the Gaussian filter against scipy, the cost against a hand computation, bad input."""

import numpy as np
import pytest
import scipy.ndimage
import torch

from bayessim_exp.errors import ConfigError, DataError
from bayessim_exp.inference.simopt.discrepancy import Discrepancy, DiscrepancyConfig, smooth_in_time

NAMES = ("x", "v", "angle")


def config(**changes) -> DiscrepancyConfig:
    base = dict(l1_weight=0.5, l2_weight=1.0, smoothing_sigma=5.0, smoothing_truncate=4.0, observed=None, weights={})
    return DiscrepancyConfig(**{**base, **changes})


@pytest.mark.parametrize("sigma, truncate", [(5.0, 4.0), (1.5, 2.0), (3.0, 10.0)])
def test_smoothing_matches_scipy_gaussian_filter(sigma, truncate):
    x = torch.randn(2, 4, 23, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    expected = scipy.ndimage.gaussian_filter1d(x.numpy(), sigma, axis=-2, mode="nearest", truncate=truncate)
    np.testing.assert_allclose(smooth_in_time(x, sigma, truncate).numpy(), expected, rtol=1e-12, atol=1e-12)


def test_cost_matches_a_hand_computation_without_smoothing():
    real = torch.tensor([[[0.0, 0.0, 0.0], [2.0, 4.0, 1.0], [4.0, 8.0, 2.0]]], dtype=torch.float64)  # M=1, T+1=3
    scale = real[0].std(0)  # per dimension over the real steps
    sim = real[None] + torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)  # a constant offset, N=1
    d = config(smoothing_sigma=0.0, weights={"v": 3.0})
    e = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64) / scale * torch.tensor([1.0, 3.0, 1.0], dtype=torch.float64)
    expected = 3 * (0.5 * e.abs().sum() + 1.0 * (e**2).sum())  # 3 steps, each with the same offset
    assert float(Discrepancy(d, NAMES, real)(sim)) == pytest.approx(float(expected))


def test_cost_is_zero_at_the_real_trajectory_and_averages_over_real_trajectories():
    g = torch.Generator().manual_seed(1)
    real = torch.randn(2, 30, 3, generator=g, dtype=torch.float64)
    disc = Discrepancy(config(), NAMES, real)
    off = real.clone()
    off[1] += 1.0
    costs = disc(torch.stack([real, off]))
    assert costs[0] == 0.0
    # a constant offset of 1 on the second real trajectory only: the filter keeps constants
    e = 1.0 / real.reshape(-1, 3).std(0)
    assert float(costs[1]) == pytest.approx(float(30 * (0.5 * e.sum() + (e**2).sum()) / 2))


def test_partial_observations_ignore_the_rest():
    g = torch.Generator().manual_seed(2)
    real = torch.randn(1, 20, 3, generator=g, dtype=torch.float64)
    sim = real[None].clone()
    sim[..., 1] += 5.0  # only v differs
    assert float(Discrepancy(config(observed=["x", "angle"]), NAMES, real)(sim)) == 0.0
    assert float(Discrepancy(config(observed=["v"]), NAMES, real)(sim)) > 0.0
    assert float(Discrepancy(config(weights={"v": 0.0}), NAMES, real)(sim)) == 0.0


def test_unknown_observation_names_are_errors_with_a_suggestion():
    real = torch.zeros(1, 5, 3)
    with pytest.raises(ConfigError, match="did you mean angle"):
        Discrepancy(config(observed=["angel"]), NAMES, real)
    with pytest.raises(ConfigError, match="observations: x, v, angle"):
        Discrepancy(config(weights={"pos": 1.0}), NAMES, real)


@pytest.mark.parametrize("changes, match", [
    ({"l1_weight": 0.0, "l2_weight": 0.0}, "not both 0"),
    ({"l1_weight": -1.0}, ">= 0"),
    ({"smoothing_sigma": -1.0}, "smoothing_sigma >= 0"),
    ({"weights": {"x": -2.0}}, "weights must be"),
    ({"observed": []}, "observed is empty"),
])
def test_bad_config_is_refused(changes, match):
    with pytest.raises(ConfigError, match=match):
        config(**changes).validate()


def test_mismatched_shapes_are_refused():
    real = torch.randn(2, 10, 3, dtype=torch.float64)
    with pytest.raises(DataError, match=r"\[M, T\+1, 3\]"):
        Discrepancy(config(), NAMES, real[..., :2])
    with pytest.raises(DataError, match=r"\[N, 2, 10, S\]"):
        Discrepancy(config(), NAMES, real)(torch.zeros(4, 1, 10, 3))
    with pytest.raises(DataError, match="NaN"):
        Discrepancy(config(), NAMES, torch.full((1, 10, 3), float("nan")))

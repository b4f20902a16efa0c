"""The escapes' reads (inference/bayessim/escape.py) on a linear simulator whose real data lie beyond its
simulations: `linear` extrapolates to the truth, `nearest` steps toward it from inside the simulations, `both` keeps
the two Gaussians."""

import pytest
import torch

from bayessim_exp.inference.bayessim.escape import INFLATE, read_at

D, F, N = 3, 8, 4000
TRUTH = torch.tensor([3.5, -3.0, 0.5], dtype=torch.float64)  # the first two beyond every simulation's |u| < 2.5


def _data(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    mixing = torch.randn(F, D, generator=g, dtype=torch.float64)

    def simulate(u: torch.Tensor) -> torch.Tensor:
        return u @ mixing.T + 0.1 * torch.randn(len(u), F, generator=g, dtype=torch.float64)

    u = (2.5 * (2 * torch.rand(N + 1000, D, generator=g, dtype=torch.float64) - 1))
    x = simulate(u)
    return x[:N], u[:N], x[N:], u[N:], simulate(TRUTH.repeat(2, 1))


def test_the_linear_read_extrapolates_to_the_truth_with_its_held_out_error_widened():
    x_fit, u_fit, x_check, u_check, x_real = _data()
    means, covs = read_at(x_fit, u_fit, x_check, u_check, x_real, "linear")
    assert means.shape == (1, D) and covs.shape == (1, D, D)
    std = covs[0].diagonal().sqrt()
    assert ((means[0] - TRUTH).abs() < 3 * std).all()
    # the widened error is INFLATE times the ridge's held-out error (std about 0.02 here), not the prior's width
    assert (std < 0.5).all() and (std > INFLATE ** 0.5 * 0.005).all()


def test_the_nearest_read_stays_among_the_simulations_and_both_keeps_the_two_reads():
    x_fit, u_fit, x_check, u_check, x_real = _data()
    nearest, nearest_cov = read_at(x_fit, u_fit, x_check, u_check, x_real, "nearest")
    linear, linear_cov = read_at(x_fit, u_fit, x_check, u_check, x_real, "linear")
    means, covs = read_at(x_fit, u_fit, x_check, u_check, x_real, "both")
    assert (nearest[0].abs() <= 2.5).all()  # a step toward the truth, inside the simulated range
    assert nearest[0][0] > 1.5 and nearest[0][1] < -1.5
    torch.testing.assert_close(means, torch.cat([linear, nearest]))
    torch.testing.assert_close(covs, torch.cat([linear_cov, nearest_cov]))


def test_an_escape_that_reads_nothing_is_refused():
    with pytest.raises(ValueError, match="reads nothing"):
        read_at(*_data(), "posterior")

"""The escapes' reads (inference/bayessim/escape.py) on a linear simulator whose real data lie beyond its
simulations: `linear` extrapolates to the truth, `nearest` steps toward it from inside the simulations."""

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
    mean, cov = read_at(x_fit, u_fit, x_check, u_check, x_real)
    assert mean.shape == (D,) and cov.shape == (D, D)
    std = cov.diagonal().sqrt()
    assert ((mean - TRUTH).abs() < 3 * std).all()
    # the covariance is INFLATE times that of the held-out errors (least squares: the penalty hardly matters with
    # 4,000 rows of 8 features), not the prior's width
    design = torch.cat([x_fit, torch.ones(len(x_fit), 1, dtype=x_fit.dtype)], 1)
    weights = torch.linalg.lstsq(design, u_fit).solution
    errors = u_check - torch.cat([x_check, torch.ones(len(x_check), 1, dtype=x_check.dtype)], 1) @ weights
    expected = INFLATE * torch.cov(errors.T)
    torch.testing.assert_close(cov, expected, rtol=0.05, atol=0.05 * float(expected.diagonal().max()))


def test_the_nearest_read_steps_toward_the_real_data_from_inside_the_simulations():
    mean, cov = read_at(*_data(), nearest=True)
    assert (mean.abs() <= 2.5).all()  # a step toward the truth, inside the simulated range
    assert mean[0] > 1.5 and mean[1] < -1.5
    # the spread of the nearest simulations, widened: wider than the linear read's error, narrower than the prior's
    assert (cov.diagonal().sqrt() > 0.3).all() and (cov.diagonal().sqrt() < INFLATE ** 0.5 * 2.5 / 3 ** 0.5).all()

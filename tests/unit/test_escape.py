"""The escapes' reads (inference/bayessim/escape.py) on simulators whose real data lie beyond their simulations:
on a linear one `linear` extrapolates to the truth, `nearest` steps toward it from inside the simulations; on a
convex one the linear read overshoots, and only its distance beyond the simulations keeps the truth in its region."""

import torch

from bayessim_exp.inference.bayessim.escape import INFLATE, beyond, read_at

D, F, N = 3, 8, 4000
TRUTH = torch.tensor([3.5, -3.0, 0.5], dtype=torch.float64)  # the first two beyond every simulation's |u| < 2.5


def _data(seed: int = 0, response=lambda u: u):
    g = torch.Generator().manual_seed(seed)
    mixing = torch.randn(F, D, generator=g, dtype=torch.float64)

    def simulate(u: torch.Tensor) -> torch.Tensor:
        return response(u) @ mixing.T + 0.1 * torch.randn(len(u), F, generator=g, dtype=torch.float64)

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
    # 4,000 rows of 8 features), not the prior's width, plus the square of the read's distance beyond the simulated
    # range, here about 1 and 0.5 in the first two coordinates
    design = torch.cat([x_fit, torch.ones(len(x_fit), 1, dtype=x_fit.dtype)], 1)
    weights = torch.linalg.lstsq(design, u_fit).solution
    errors = u_check - torch.cat([x_check, torch.ones(len(x_check), 1, dtype=x_check.dtype)], 1) @ weights
    outside = beyond(mean, u_fit)
    assert (outside[:2] > 0.3).all() and outside[2] == 0
    expected = INFLATE * torch.cov(errors.T) + torch.diag(outside**2)
    torch.testing.assert_close(cov, expected, rtol=0.05, atol=0.05 * float(expected.diagonal().max()))


def test_a_linear_read_that_overshoots_beyond_the_simulations_keeps_the_truth_in_its_region():
    """Summaries cubic in u: fitted on |u| < 2.5, the linear read of a truth at 3.5 lands near 9, five of its held-out
    error's standard deviations away (outside the 99.9 % region the next round proposes from); widened by its
    distance beyond the simulations, the truth is within one."""
    x_fit, u_fit, x_check, u_check, x_real = _data(response=lambda u: u**3)
    mean, cov = read_at(x_fit, u_fit, x_check, u_check, x_real)
    assert mean[0] > 6.0  # the overshoot this test is about
    z = (mean - TRUTH) / cov.diagonal().sqrt()
    assert (z.abs() < 1.5).all()


def test_the_nearest_read_steps_toward_the_real_data_from_inside_the_simulations():
    mean, cov = read_at(*_data(), nearest=True)
    assert (mean.abs() <= 2.5).all()  # a step toward the truth, inside the simulated range
    assert mean[0] > 1.5 and mean[1] < -1.5
    # the spread of the nearest simulations, widened: wider than the linear read's error, narrower than the prior's
    assert (cov.diagonal().sqrt() > 0.3).all() and (cov.diagonal().sqrt() < INFLATE ** 0.5 * 2.5 / 3 ** 0.5).all()

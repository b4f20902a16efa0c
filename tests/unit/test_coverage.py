"""Acceptance 2: expected coverage of 50% and 90% regions within 0.07 of nominal (mdnn and flow).

Cheap simulator: the linear-Gaussian one; 4000 training and 500 held-out simulations, seeds fixed.
"""

import pytest
import torch
from linear_gaussian import gaussian_draws
from test_models import CONFIGS, PRIOR, SIM

from bayessim_exp.diagnostics.coverage import expected_coverage
from bayessim_exp.registry import build


class _Oracle:
    """The exact posterior: coverage must be nominal up to Monte Carlo error."""

    def conditional(self, x):
        from bayessim_exp.distributions.mixture import GaussianMixture

        mean, cov = SIM.posterior(PRIOR.loc, PRIOR.covariance_matrix, x[None])
        return GaussianMixture(torch.zeros(1), mean[None], cov[None])


def _held_out():
    theta = gaussian_draws(PRIOR.loc, PRIOR.covariance_matrix, 500, seed=100)
    return theta, SIM.simulate(theta, seed=101)


def _check(report):
    for kind in ("hpd", "central"):
        for level in ("0.5", "0.9"):
            assert abs(report[kind][level] - float(level)) < 0.07, report


def test_exact_posterior_is_calibrated():
    _check(expected_coverage(_Oracle(), *_held_out(), num_samples=500))


@pytest.mark.parametrize("name", ["mdnn", "flow"])
def test_trained_models_are_calibrated(name):
    torch.set_num_threads(1)
    theta = gaussian_draws(PRIOR.loc, PRIOR.covariance_matrix, 4000, seed=0)
    model = build("model", {"name": name, **CONFIGS[name]}, theta_dim=2, x_dim=3)
    model.fit(theta, SIM.simulate(theta, seed=1), seed=0, label="test")
    _check(expected_coverage(model, *_held_out(), num_samples=500))

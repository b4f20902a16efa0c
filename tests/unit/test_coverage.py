"""Expected coverage against a known posterior, in the default parameter space (probit).

The prior is uniform on a box; the simulator is linear-Gaussian in u, the parameters' probit (x = A u + b +
noise), so the posterior in u is Gaussian in closed form. 2,000 held-out pairs: a coverage's standard error
is 0.007 at 90 %, 0.011 at 50 %, so a band of +-0.03 (90 %) and +-0.045 (50 %) holds a calibrated model's
coverage at better than 4 standard errors and fails an overconfident 0.83 (or 0.44).
"""

import pytest
import torch
from linear_gaussian import LinearGaussian

from bayessim_exp import api
from bayessim_exp.diagnostics.coverage import expected_coverage
from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.distributions.probit import ProbitTransform

PRIOR = BoxUniform(torch.tensor([0.5, 0.25], dtype=torch.float64), torch.tensor([2.0, 1.0], dtype=torch.float64))
PROBIT = ProbitTransform(PRIOR)
SIM = LinearGaussian(torch.tensor([[1.0, 0.5], [-0.3, 2.0], [0.7, 0.0]]), torch.tensor([0.1, -0.2, 0.3]),
                     0.3 * torch.eye(3))
BAND = {"0.5": 0.045, "0.9": 0.03}


class _Oracle:
    """The exact posterior in u: coverage must be nominal up to sampling error."""

    def conditional(self, x):
        mean, cov = SIM.posterior(torch.zeros(2), torch.eye(2), x[None])
        return GaussianMixture(torch.zeros(1), mean[None], cov[None])


def _pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    theta = PRIOR.low + torch.rand(n, 2, dtype=torch.float64, generator=g) * (PRIOR.high - PRIOR.low)
    return theta, SIM.simulate(PROBIT.to_probit(theta), seed=seed + 1)


def _check(report, kinds=("hpd", "central")):
    for kind in kinds:
        for level, half in BAND.items():
            assert abs(report[kind][level] - float(level)) < half, report


def _held_out():
    theta, x = _pairs(2000, seed=100)
    return PROBIT.to_probit(theta), x


def test_exact_posterior_is_calibrated():
    _check(expected_coverage(_Oracle(), *_held_out(), num_samples=500))


def test_an_overconfident_posterior_fails_the_band():
    """The exact posterior with its covariance shrunk by 0.6: 90 % regions cover about 0.80."""

    class Narrow(_Oracle):
        def conditional(self, x):
            exact = super().conditional(x)
            return GaussianMixture(torch.zeros(1), exact.means, 0.6 * exact.covs)

    report = expected_coverage(Narrow(), *_held_out(), num_samples=500)
    assert report["hpd"]["0.9"] < 0.9 - BAND["0.9"] and report["hpd"]["0.5"] < 0.5 - BAND["0.5"], report


@pytest.mark.parametrize("name", ["mdnn", pytest.param("mdrff", marks=pytest.mark.slow)])  # mdrff: over 10 s
def test_trained_models_are_calibrated_in_probit_space(name):
    """The mixture models at their defaults (calibrated spread), fitted in probit space as the pipeline fits them."""
    torch.set_num_threads(1)
    theta, x = _pairs(4000, seed=0)
    fitted = api.fit_posterior_model(name, theta, x, prior=PRIOR, probit=True)
    _check(expected_coverage(fitted.model, *_held_out(), num_samples=500), kinds=("hpd",))

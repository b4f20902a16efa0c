"""Coverage near the real data (diagnostics/local_coverage.py) against a linear-Gaussian model whose posteriors are
known: nominal for the exact model wherever the real data lie, far below it for a model biased there, and the
guard fails the round on it."""

import pytest
import torch

from bayessim_exp.diagnostics.guard import check_posterior, coverage_band
from bayessim_exp.diagnostics.local_coverage import local_coverage
from bayessim_exp.distributions.hpd import hpd_level
from bayessim_exp.distributions.independent import GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.inference.bayessim.correction import posterior

NOISE = 0.5  # x = theta + N(0, NOISE^2) in one dimension, theta ~ N(0, 1): one trajectory's posterior has variance 0.2
PRIOR = GaussianPrior(torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.float64))
PAIRS = 400  # a 90 % share's standard error is 0.015
LEVELS = (0.5, 0.9)


def _single(x: torch.Tensor, shift: float) -> GaussianMixture:
    """The posterior given one x, its mean moved by `shift` posterior standard deviations (0: exact)."""
    var = NOISE**2 / (1 + NOISE**2)
    return GaussianMixture(torch.zeros(1), (x / (1 + NOISE**2) + shift * var**0.5)[None], var * torch.ones(1, 1, 1))


def _simulator(shift: float, seed: int):
    g = torch.Generator().manual_seed(seed)

    def simulate(theta: torch.Tensor) -> tuple[torch.Tensor, list]:
        x = theta + NOISE * torch.randn(theta.shape, dtype=torch.float64, generator=g)
        return torch.ones(len(theta), dtype=torch.bool), [_single(x_j, shift) for x_j in x]

    return simulate


def _local(x_real: list[float], shift: float = 0.0) -> dict:
    real = [_single(torch.tensor([x], dtype=torch.float64), shift) for x in x_real]
    return local_coverage(lambda qs: posterior(qs, PRIOR), real, _simulator(shift, seed=1), PAIRS, LEVELS, 500, seed=2)


def _inside_band(record: dict) -> bool:
    return all(coverage_band(float(level), record["count"])[0] <= share <= coverage_band(float(level), record["count"])[1]
               for level, share in record["hpd"].items())


@pytest.mark.parametrize("x_real", [[0.0], [3.0], [-2.5, -2.9, -2.2]])
def test_the_exact_model_is_covered_wherever_the_real_data_lie(x_real):
    """In the prior's tail too (x = 3: the posterior's mean 2.4 is 2.4 prior standard deviations out)."""
    record = _local(x_real)
    assert record["count"] == PAIRS and _inside_band(record), record
    assert check_posterior(1.0, None, 0, local=record).ok


def test_placing_the_draws_in_their_own_trajectory_alone_is_not_calibrated_in_the_tail():
    """Why the check adds the simulated trajectory to the real ones: the posterior given x_j alone shrinks toward the
    prior. At x = 3 a draw theta_j ~ N(2.4, 0.2) sits 0.2 theta_j = 0.48 from the mean of its posterior given x_j,
    with spread sqrt(0.04 * 0.2 + 0.64 * 0.25) = 0.41 against the posterior's 0.447: 73 % inside the 90 % region."""
    g = torch.Generator().manual_seed(3)
    exact = posterior([_single(torch.tensor([3.0], dtype=torch.float64), 0.0)], PRIOR)
    theta = exact.sample((PAIRS,), generator=g).double()
    _, alone = _simulator(0.0, seed=1)(theta)
    levels = torch.tensor([hpd_level(q, t[None], q.sample((500,), generator=g).double(), g) for q, t in zip(alone, theta)])
    share = float((levels < 0.9).double().mean())
    assert share < coverage_band(0.9, PAIRS)[0] and share == pytest.approx(0.73, abs=0.06)


def test_a_model_biased_near_the_real_data_fails_the_guard():
    """Every per-trajectory posterior b = 1.5 of its standard deviations (0.67) too high: theta_j ~ N(0.8 x + b, 0.2)
    and the posterior given x and x_j has precision 5 + 5 - 1 = 9 and mean (4 x + 4 x_j + 10 b) / 9, so theta_j lies
    5 b / 9 = 0.37 (1.1 of that posterior's standard deviations) off its centre on average: 70 % inside the 90 %
    region."""
    record = _local([0.4], shift=1.5)
    assert record["hpd"]["0.9"] < coverage_band(0.9, PAIRS)[0] and record["hpd"]["0.9"] == pytest.approx(0.70, abs=0.06)
    report = check_posterior(1.0, {"0.5": 0.5, "0.9": 0.9}, 1000, local=record)
    assert report.failed and "overconfident near the real data" in report.warnings[0]


def test_no_simulation_left_is_no_finding():
    record = local_coverage(lambda qs: posterior(qs, PRIOR), [_single(torch.zeros(1, dtype=torch.float64), 0.0)],
                            lambda theta: (torch.zeros(len(theta), dtype=torch.bool), []), 10, LEVELS, 100, seed=0)
    assert record == {"count": 0, "hpd": None} and check_posterior(1.0, None, 0, local=record).ok

"""Real data outside the training simulations (diagnostics/extrapolation.py): the p-values are uniform when the real
summaries are drawn like the held-out ones (the guard's false-alarm rate is alpha), stay below it when several real
summaries share one hidden parameter vector, and a system in the joint tail of independent parameters is found where
the count of features outside the simulated range (mismatch.summaries_outside) sees nothing unusual."""

import pytest
import torch

from bayessim_exp.diagnostics.extrapolation import inputs_outside
from bayessim_exp.diagnostics.guard import check_posterior
from bayessim_exp.diagnostics.mismatch import summaries_outside

D = 24  # parameters, each uniform on [0.1, 10] like ShadowHand's 24 link-mass multipliers
REPEATS = 400  # a share of 0.05 has a standard error of 0.011
ALPHA = 0.05


def _simulate(theta: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    """Summaries that measure an acceleration, force over total mass, precisely and each parameter roughly: a hand
    whose motion reveals its total mass better than how the mass is shared between its links."""
    acceleration = 100 / theta.sum(1, keepdim=True) + 0.05 * torch.randn(len(theta), 1, generator=g, dtype=torch.float64)
    each = theta + 3.0 * torch.randn(theta.shape, generator=g, dtype=torch.float64)
    return torch.cat([acceleration, each], 1)


def _prior(n: int, g: torch.Generator) -> torch.Tensor:
    return 0.1 + 9.9 * torch.rand(n, D, generator=g, dtype=torch.float64)


def _p_values(real_theta, g: torch.Generator, train: int = 2000, held: int = 500) -> dict:
    theta = _prior(train, g)
    return inputs_outside(_simulate(real_theta, g), _simulate(theta, g), theta, _simulate(_prior(held, g), g), ALPHA)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_p_values_are_uniform_when_the_real_data_are_drawn_like_the_held_out_ones():
    g = torch.Generator().manual_seed(0)
    p = torch.tensor([_p_values(_prior(1, g), g)["p_value"][0] for _ in range(REPEATS)])
    for level in (0.05, 0.25, 0.5, 0.75):  # the empirical CDF within 3 standard errors of the uniform's
        share = float((p <= level).double().mean())
        assert abs(share - level) < 3 * (level * (1 - level) / REPEATS) ** 0.5, (level, share)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_several_real_summaries_of_one_hidden_system_raise_at_most_alpha_false_alarms():
    """Three trajectories of one system drawn from the prior (a calibration study's truth) are not independent; the
    Bonferroni threshold alpha / n holds whatever their dependence."""
    g = torch.Generator().manual_seed(1)
    flagged = [bool(_p_values(_prior(1, g).repeat(3, 1), g)["flagged"]) for _ in range(REPEATS)]
    rate = sum(flagged) / REPEATS
    assert rate <= ALPHA + 2 * (ALPHA * (1 - ALPHA) / REPEATS) ** 0.5, rate


def test_a_system_in_the_joint_tail_is_flagged_where_the_range_count_sees_nothing_unusual():
    """Every parameter at 1.8, the 17th percentile of its range, each unremarkable: the total mass, 43 against a prior
    mean of 121 and a standard deviation of 14, is far out jointly, and its acceleration 2.3 against 0.83 +- 0.1
    lies beyond every simulation. One feature outside the range is as common among the held-out simulations as not to
    count (p > alpha / n); its distance puts each real trajectory beyond every held-out one."""
    g = torch.Generator().manual_seed(2)
    theta = _prior(2000, g)
    train, held = _simulate(theta, g), _simulate(_prior(500, g), g)
    real = _simulate(torch.full((3, D), 1.8, dtype=torch.float64), g)
    outside = summaries_outside(real, train, held)
    assert outside["features_outside"] == [1, 1, 1] and min(outside["p_value"]) > 0.01 / 3, outside
    record = inputs_outside(real, train, theta, held, 0.01)
    assert record["flagged"] == [0, 1, 2] and max(record["p_value"]) == 1 / 501, record


def test_a_deviation_in_directions_the_simulations_never_vary_is_not_a_finding():
    """Real summaries off the simulations only where the simulator is deterministic (a relation its integrator fixes;
    here a feature equal to another) say nothing about the parameters: the regression's predictions ignore that
    direction, though a distance in the raw summaries would put them beyond every simulation."""
    g = torch.Generator().manual_seed(4)

    def with_copy(x: torch.Tensor, offset: float) -> torch.Tensor:
        return torch.cat([x, x[:, :1] + offset], 1)

    theta = _prior(2000, g)
    train, held = with_copy(_simulate(theta, g), 0.0), with_copy(_simulate(_prior(500, g), g), 0.0)
    real = with_copy(_simulate(_prior(200, g), g), 0.05)
    p = torch.tensor(inputs_outside(real, train, theta, held, ALPHA)["p_value"])
    assert abs(float((p <= 0.25).double().mean()) - 0.25) < 3 * (0.25 * 0.75 / 200) ** 0.5


@pytest.mark.parametrize("flagged", [[], [1]])
def test_the_guard_fails_a_round_whose_real_data_lie_outside(flagged):
    record = {"distance": [30.0, 80.0], "p_value": [0.4, 0.001], "held_out_median": 31.0, "alpha": 0.01,
              "flagged": flagged}
    report = check_posterior(1.0, {"0.9": 0.9}, 1000, extrapolation=record)
    assert report.failed == bool(flagged) and report.ok == (not flagged)
    if flagged:
        assert "outside the simulations the model was trained on: real trajectories [1]" in report.warnings[0]

"""Priors: support, normalisation, sampling, and the registry entries."""

import torch

from bayessim_exp.distributions.independent import GaussianPrior, LogUniform
from bayessim_exp.registry import build

LOW, HIGH = torch.tensor([0.1, 2.0], dtype=torch.float64), torch.tensor([10.0, 3.0], dtype=torch.float64)


def _mass_on_grid(dist, n=801):
    g0 = torch.linspace(LOW[0], HIGH[0], n, dtype=torch.float64)
    g1 = torch.linspace(LOW[1], HIGH[1], n, dtype=torch.float64)
    grid = torch.stack(torch.meshgrid(g0, g1, indexing="ij"), -1)
    dens = dist.log_prob(grid).exp()
    return torch.trapezoid(torch.trapezoid(dens, g1, dim=1), g0).item()


def test_loguniform_is_normalised_and_uniform_in_log_space():
    prior = LogUniform(LOW, HIGH)
    assert abs(_mass_on_grid(prior) - 1.0) < 1e-2
    s = prior.sample((20000,))
    assert ((s >= LOW) & (s <= HIGH)).all()
    frac_below_1 = (s[:, 0] < 1.0).double().mean().item()  # log-midpoint of [0.1, 10]
    assert abs(frac_below_1 - 0.5) < 0.02
    assert prior.log_prob(torch.tensor([[20.0, 2.5]])).item() == -torch.inf


def test_truncated_gaussian_is_normalised_and_stays_in_the_box():
    prior = GaussianPrior(torch.tensor([1.0, 2.9]), torch.tensor([2.0, 0.3]), LOW, HIGH)
    assert abs(_mass_on_grid(prior) - 1.0) < 1e-3
    s = prior.sample((20000,))
    assert ((s >= LOW) & (s <= HIGH)).all()
    grid = torch.linspace(LOW[0], HIGH[0], 4001, dtype=torch.float64)
    marg = torch.distributions.Normal(1.0, 2.0).log_prob(grid).exp()
    mean0 = (torch.trapezoid(marg * grid, grid) / torch.trapezoid(marg, grid)).item()
    assert abs(s[:, 0].mean().item() - mean0) < 0.04


class _Spec:
    names = ["mass", "length"]
    low, high = LOW.numpy(), HIGH.numpy()


def test_registry_builds_every_prior_from_its_yaml_keys():
    for cfg in ({"name": "uniform"}, {"name": "loguniform"}, {"name": "gaussian", "stds_per_range": 4.0, "truncate": True}):
        prior = build("prior", cfg, spec=_Spec())
        torch.testing.assert_close(prior.low, LOW)
        assert torch.isfinite(prior.log_prob(prior.sample((10,)))).all()
    untruncated = build("prior", {"name": "gaussian", "truncate": False}, spec=_Spec())
    assert untruncated.low is None
    torch.testing.assert_close(untruncated.scale, (HIGH - LOW) / 4)


def test_prior_moments_match_their_samples():
    for prior in (LogUniform(LOW, HIGH), GaussianPrior(torch.tensor([1.0, 2.9]), torch.tensor([2.0, 0.3]), LOW, HIGH)):
        torch.manual_seed(0)
        s = prior.sample((200_000,))
        torch.testing.assert_close(prior.mean, s.mean(0), atol=0.02, rtol=0)
        torch.testing.assert_close(prior.stddev, s.std(0), atol=0.02, rtol=0)

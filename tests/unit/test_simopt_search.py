"""SimOpt's search on a simulator whose discrepancy is minimised at known parameters (acceptance 1)."""

import dataclasses
import math

import pytest
import torch
from torch.distributions import MultivariateNormal, kl_divergence

from bayessim_exp.errors import ConfigError, PosteriorError
from bayessim_exp.inference.simopt.discrepancy import Discrepancy
from bayessim_exp.inference.simopt.reps import Gaussian
from bayessim_exp.inference.simopt.search import SimOptConfig, initial_gaussian, search
from bayessim_exp.registry import parse_params

LOW = torch.tensor([0.1, 1.0, 0.5], dtype=torch.float64)
HIGH = torch.tensor([1.0, 4.0, 2.0], dtype=torch.float64)
TRUE = torch.tensor([0.4, 2.5, 1.2], dtype=torch.float64)
TIME = torch.arange(41, dtype=torch.float64) * 0.1


def shipped_config(**changes) -> SimOptConfig:
    """conf/method/simopt.yaml's config, checked as a run's (registry.parse_params), with `changes`."""
    return dataclasses.replace(parse_params("method", {"name": "simopt"})[1], **changes)


def oscillator(theta: torch.Tensor) -> torch.Tensor:
    """A damped oscillator (decay, frequency, amplitude) observed as (x, y): [N, 3] -> [N, 1, T+1, 2]."""
    decay, freq, amp = theta[:, :1], theta[:, 1:2], theta[:, 2:]
    envelope = amp * torch.exp(-decay * TIME)
    return torch.stack([envelope * torch.cos(freq * TIME), envelope * torch.sin(freq * TIME)], -1)[:, None]


def start(cfg: SimOptConfig):
    return initial_gaussian(0.5 * (LOW + HIGH), (HIGH - LOW) / math.sqrt(12), LOW, HIGH, cfg.min_std)


@pytest.mark.parametrize("kl_bound, updates", [(1.0, 10), (0.3, 20)])
def test_updates_move_the_mean_to_the_true_parameters_shrink_the_covariance_and_respect_the_kl_bound(kl_bound, updates):
    cfg = shipped_config(kl_bound=kl_bound, updates=updates)
    disc = Discrepancy(cfg.discrepancy, ("x", "y"), oscillator(TRUE[None])[0])
    first = start(cfg)
    gaussians, history = search(first, lambda theta: disc(oscillator(theta)), cfg, 200, LOW, HIGH,
                                torch.Generator().manual_seed(0))
    assert len(gaussians) == len(history) == updates
    previous = first
    for g in gaussians:  # every step, checked with torch's own KL
        kl = kl_divergence(MultivariateNormal(g.mean, g.cov), MultivariateNormal(previous.mean, previous.cov))
        assert float(kl) <= kl_bound + 1e-9
        previous = g
    assert all(h["weights_kl"] <= kl_bound + 1e-9 for h in history)
    final = gaussians[-1]
    assert ((final.mean - TRUE).abs() < 0.01 * (HIGH - LOW)).all(), final.mean
    assert (final.cov.diagonal() < 0.01 * first.cov.diagonal()).all()  # std below a tenth of the start's
    assert torch.linalg.det(final.cov) < 1e-6 * torch.linalg.det(first.cov)
    assert history[-1]["mean_cost"] < 0.05 * history[0]["mean_cost"]


def test_the_spread_stops_at_the_floor():
    cfg = shipped_config(updates=15)
    disc = Discrepancy(cfg.discrepancy, ("x", "y"), oscillator(TRUE[None])[0])
    gaussians, _ = search(start(cfg), lambda theta: disc(oscillator(theta)), cfg, 200, LOW, HIGH,
                          torch.Generator().manual_seed(1))
    floor = (cfg.min_std * (HIGH - LOW)) ** 2
    whitened = torch.linalg.eigvalsh(gaussians[-1].cov / floor.sqrt()[:, None] / floor.sqrt()[None])
    assert (whitened >= 1 - 1e-9).all()
    assert whitened.min() < 1 + 1e-3  # reached, not only respected


def test_draws_outside_the_box_are_simulated_inside_it_and_diverged_ones_get_no_weight():
    cfg = shipped_config(updates=1)
    seen = []

    def cost(theta):
        seen.append(theta)
        c = (theta - TRUE).pow(2).sum(1)
        c[:5] = float("nan")  # diverged simulations
        return c

    at_corner = Gaussian(LOW, start(cfg).cov)  # about half of every coordinate's draws fall below the box
    _, history = search(at_corner, cost, cfg, 200, LOW, HIGH, torch.Generator().manual_seed(2))
    assert ((seen[0] >= LOW) & (seen[0] <= HIGH)).all()
    assert (seen[0] == LOW).sum() > 25
    assert history[0]["diverged"] == 5


def test_no_finite_cost_is_an_error_naming_the_update():
    cfg = shipped_config(updates=2)
    with pytest.raises(PosteriorError, match="update 1: fewer than 2 of 10"):
        search(start(cfg), lambda theta: torch.full((len(theta),), float("inf")), cfg, 10, LOW, HIGH,
               torch.Generator().manual_seed(0))


@pytest.mark.parametrize("changes, match", [
    ({"updates": 0}, "updates >= 1"), ({"kl_bound": 0.0}, "kl_bound > 0"), ({"min_std": 0.3}, "min_std"),
    ({"rollout": "open"}, "allowed: closed_loop, recorded"),
])
def test_bad_config_is_refused(changes, match):
    with pytest.raises(ConfigError, match=match):
        parse_params("method", {"name": "simopt", **changes})

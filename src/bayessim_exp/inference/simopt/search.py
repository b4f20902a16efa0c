"""SimOpt's search: several REPS updates of N(mu, Sigma) against a black-box cost of parameters.

Each update draws `samples` parameters from the current Gaussian, asks the cost (in SimOpt: simulate the
policy and compare with the real observations), and moves the Gaussian by `reps.reps_update`. The
simulator only accepts parameters inside the prior's box, so draws outside it are simulated at the
nearest point of the box (clipped) but enter the update unclipped: the Gaussian itself stays untruncated,
and the cost of the box's edge pushes it back inside when the edge fits badly. Samples whose cost is not
finite (diverged simulations) get no weight.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Literal

import torch

from ...errors import ConfigError, PosteriorError
from .discrepancy import DiscrepancyConfig
from .reps import Gaussian, floor_covariance, reps_update


@dataclasses.dataclass
class SimOptConfig:
    """method=simopt; defaults in conf/method/simopt.yaml."""

    updates: int  # REPS updates per round; each draws collect.trajectories / updates parameter samples
    kl_bound: float  # epsilon: KL(new || old) per update, for the sample weights and for the Gaussian
    min_temperature: float  # lower bound on the REPS temperature, in units of the costs' standard deviation
    min_std: float  # floor on the Gaussian's spread, as a fraction of each parameter's prior range
    # closed_loop: run the round's policy on the simulator; recorded: replay the real trajectory's actions
    # (the same thing for a policy that ignores the state, such as the random collect policy, with the
    # real noise instead of fresh noise)
    rollout: Literal["closed_loop", "recorded"]
    discrepancy: DiscrepancyConfig

    def validate(self) -> None:
        if self.updates < 1:
            raise ConfigError(f"need updates >= 1, got {self.updates}")
        if not self.kl_bound > 0 or not self.min_temperature > 0:
            raise ConfigError(f"need kl_bound > 0 and min_temperature > 0, got {self.kl_bound}, {self.min_temperature}")
        if not 0 < self.min_std < 0.25:  # a uniform prior's own std is 0.29 of its range
            raise ConfigError(f"min_std is a fraction of the prior range in (0, 0.25), got {self.min_std}")
        self.discrepancy.validate()


def initial_gaussian(mean: torch.Tensor, std: torch.Tensor, low: torch.Tensor, high: torch.Tensor,
                     min_std: float) -> Gaussian:
    """N(prior mean, diag(prior variance)), its spread floored like every update's."""
    cov = floor_covariance(torch.diag(std.double() ** 2), min_std * (high - low).double())
    return Gaussian(mean.double(), cov)


def search(start: Gaussian, cost: Callable[[torch.Tensor], torch.Tensor], cfg: SimOptConfig, samples: int,
           low: torch.Tensor, high: torch.Tensor, generator: torch.Generator) -> tuple[list[Gaussian], list[dict]]:
    """`cfg.updates` REPS updates from `start`, each on `samples` draws; cost(theta [N, D] inside the box) -> [N].
    Returns the Gaussian after each update and one record per update."""
    if samples < 2:
        raise ConfigError(f"SimOpt needs at least 2 parameter samples per update, got {samples}")
    low, high = low.double(), high.double()
    min_std = cfg.min_std * (high - low)
    current, gaussians, history = start, [], []
    for u in range(cfg.updates):
        theta = current.sample(samples, generator)
        costs = cost(torch.minimum(torch.maximum(theta, low), high)).double()
        finite = torch.isfinite(costs)
        if int(finite.sum()) < 2:
            raise PosteriorError(f"SimOpt update {u + 1}: fewer than 2 of {samples} simulations gave a finite cost")
        step = reps_update(current, theta[finite], costs[finite], cfg.kl_bound, cfg.min_temperature, min_std)
        history.append({
            "update": u + 1, "mean_cost": float(costs[finite].mean()), "min_cost": float(costs[finite].min()),
            "diverged": int((~finite).sum()), "weights_kl": step.weights_kl,
            "temperature": step.temperature if math.isfinite(step.temperature) else None,  # None: all costs equal
            "gaussian_kl": step.gaussian_kl, "step_fraction": step.step_fraction,
            "effective_samples": step.effective_samples,
        })
        current = step.gaussian
        gaussians.append(current)
    return gaussians, history

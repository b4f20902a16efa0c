"""Simulations at given parameters under the collect policy, for the round's checks: driven as the real data
were where the policy replays them with noise (docs/statistics.md, 'Simulations driven like the real system')."""

from __future__ import annotations

from collections.abc import Callable

import torch

from ...sim.trajectories import Trajectories


def simulate_as_driven(sims, policy, theta: torch.Tensor, horizon: int, seed: int,
                       summaries: Callable[[Trajectories], torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """One trajectory at each theta [K, D] under the collect policy, driven as the real data were where it replays
    them: (kept [K]: neither diverged nor with a non-finite summary, summaries [K, F] in float64)."""
    traj = sims.rollout(theta, policy.without_noise() or policy, horizon, seed)
    x = summaries(traj).double()
    return ~traj.diverged.cpu() & torch.isfinite(x).all(-1), x


def predictive_summaries(sims, policy, theta: torch.Tensor, horizon: int, seed: int, summarizer, device) -> torch.Tensor:
    """The summaries of one trajectory at each theta [K, D] under the collect policy, diverged and non-finite
    ones left out (the summary predictive check)."""
    traj = sims.rollout(theta, policy, horizon, seed).to(device)
    x = summarizer(traj.select(~traj.diverged)).cpu()
    return x[torch.isfinite(x).all(1)]

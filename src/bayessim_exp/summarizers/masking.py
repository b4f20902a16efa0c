"""Masks for trajectories that ended early: which steps count, and values held past the end.

`Trajectories.valid[:, t]` is True while step t was simulated; it is a prefix (False from
termination on), so one count per trajectory says where its valid part ends.
"""

from __future__ import annotations

import torch

from ..sim.trajectories import Trajectories


def valid_steps(traj: Trajectories) -> torch.Tensor:
    """[N] number of valid control steps n; states 0..n and actions 0..n-1 are real data."""
    return traj.valid.sum(1)


def held_states(traj: Trajectories) -> torch.Tensor:
    """[N, T+1, S] states with every state after the last valid one replaced by it."""
    n = valid_steps(traj)
    idx = torch.arange(traj.horizon + 1, device=n.device).minimum(n[:, None])
    return traj.states.gather(1, idx[..., None].expand(-1, -1, traj.states.shape[-1]))


def held_actions(traj: Trajectories, points: int) -> torch.Tensor:
    """[N, points, A] the action in force at time p: a[p] while valid, then the last valid one.

    `points` may be T+1 (one per state): the final state keeps the last action. A trajectory
    with no valid step gets its (meaningless) first action everywhere, still finite.
    """
    n = valid_steps(traj)
    idx = torch.arange(points, device=n.device).minimum((n[:, None] - 1).clamp_min(0))
    return traj.actions.gather(1, idx[..., None].expand(-1, -1, traj.actions.shape[-1]))

"""Returns of a trained actor on fixed parameters (the surrogate real system), one full episode per slot.

Written on `Simulator.rollout`, so it runs on any backend; each slot starts from its own draw of the
task's reset distribution and the actor acts deterministically (its mean action).
"""

from __future__ import annotations

import numpy as np
import torch

from ..sim.base import Simulator
from .actor_policy import ActorPolicy


def episode_returns(actor, sim: Simulator, params: np.ndarray, seed: int) -> torch.Tensor:
    """Undiscounted return [num_envs] of one episode (the task's episode_length) in every slot of `sim`."""
    policy = ActorPolicy(actor, sim.task.action_dim, seed, random_share=0.0)
    rows = np.repeat(np.asarray(params, dtype=np.float64)[None], sim.num_envs, axis=0)
    traj = sim.rollout(rows, policy, sim.task.cfg.episode_length, seed=seed)
    return traj.rewards.sum(1).double().cpu()


def summary(returns: torch.Tensor) -> dict:
    """mean, min, max (and std) of episode returns, as recorded in results.json."""
    return {"mean": float(returns.mean()), "min": float(returns.min()), "max": float(returns.max()),
            "std": float(returns.std()) if len(returns) > 1 else 0.0}

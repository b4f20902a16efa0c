"""Replaying recorded trajectories in the simulator: each one's own initial state and actions.

A recorded trajectory's states depend on the parameters, its initial state and its actions. A
check that draws fresh initial states and actions compares mostly their randomness; replaying the
recorded ones leaves only the parameters (and whatever the model does not represent) to explain a
difference. `replay` is the one place that calls the simulator for this.
"""

from __future__ import annotations

import torch

from ..policies import OpenLoopPolicy
from ..sim.pool import SimulatorPool
from ..sim.trajectories import Trajectories


def replay(sims: SimulatorPool, params: torch.Tensor, recorded: Trajectories, which: torch.Tensor) -> Trajectories:
    """Rollout k at params[k] from recorded trajectory which[k]'s initial state, under its actions.

    params [N, D]; which [N] indexes recorded's trajectories. The task must map an observation to a
    simulator state (Task.state_from_observation)."""
    state = sims.task.state_from_observation(recorded.states[which, 0].double().cpu().numpy())
    if state is None:
        raise ValueError(f"task {sims.task.name} cannot map an observation to a simulator state")
    policy = OpenLoopPolicy(recorded.actions[which].float().cpu())
    return sims.rollout(params.double(), policy, recorded.horizon, seed=0, state=state)

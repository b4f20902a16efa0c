"""Replaying recorded trajectories in the simulator: each one's own initial state and actions.

A recorded trajectory's states depend on the parameters, its initial state and its actions. A
check that draws fresh initial states and actions compares mostly their randomness; replaying the
recorded ones leaves only the parameters (and whatever the model does not represent) to explain a
difference. `replay` is the one place that calls the simulator for this.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from ..sim.trajectories import Trajectories


class OpenLoopPolicy:
    """Plays recorded actions [N, T, A] step by step, whatever the observations."""

    def __init__(self, actions: torch.Tensor):
        self.actions = actions

    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return self.actions[:, t]


def replay(make_sim: Callable, task, params: torch.Tensor, recorded: Trajectories,
           which: torch.Tensor) -> Trajectories:
    """Rollout k at params[k] from recorded trajectory which[k]'s initial state, under its actions.

    params [N, D]; which [N] indexes recorded's trajectories. Raises NotImplementedError when the
    task cannot map an observation to a simulator state (Task.state_from_obs)."""
    first_obs = recorded.states[which, 0].double().numpy()
    state = task.state_from_obs(first_obs)
    sim = make_sim(task, len(which))
    return sim.rollout(params.double().numpy(), OpenLoopPolicy(recorded.actions[which].float()), recorded.horizon,
                       np.random.default_rng(0), state=state)

"""Simulated counterparts of the real roll-outs: every parameter sample is rolled out once from every real
trajectory's initial state, for the real trajectory's horizon.

The initial state comes from the real trajectory's first observation where the task can map an observation
back to its state (`Task.state_from_observation`); otherwise from the task's reset distribution, which
adds the spread of initial states to the discrepancy. Actions come from the round's policy run closed loop
on the simulator, or from the real trajectory's recorded actions (`recorded`), which for a policy that
ignores the state (the random collect policy) is the same policy with the real noise instead of fresh noise.
"""

from __future__ import annotations

import logging

import numpy as np
import torch

from ...errors import ConfigError
from ...policies import OpenLoopPolicy
from ...sim.pool import SimulatorPool
from ...sim.trajectories import Trajectories

log = logging.getLogger(__name__)


def simulate_like_real(sims: SimulatorPool, params: torch.Tensor, real: Trajectories, policy, rollout: str,
                       seed: int) -> torch.Tensor:
    """Observations [N, M, T+1, S] of params [N, D] rolled out from each of the M real starts; NaN for
    simulations that diverged (SimOpt gives them no weight)."""
    n, m = len(params), real.num
    task = sims.task
    rows = params.double().repeat_interleave(m, 0).numpy()  # row i * m + j: sample i from real start j
    start = task.state_from_observation(real.states[:, 0].double().cpu().numpy())
    if start is None:
        log.warning("task %s cannot restart from an observed state; SimOpt simulations start from its reset "
                    "distribution instead", task.name)
    state = None if start is None else {f: np.tile(v, (n,) + (1,) * (v.ndim - 1)) for f, v in start.items()}
    acting = OpenLoopPolicy(real.actions.repeat(n, 1, 1)) if rollout == "recorded" else policy
    if acting.plan is not None:  # the pool would start each row from a recorded trajectory's state, not the real start's
        raise ConfigError("SimOpt's closed_loop rollout runs the round's policy step by step; policy=replay "
                          "replays recorded trajectories: use method.rollout=recorded")
    traj = sims.rollout(rows, acting, real.horizon, seed, state=state)  # the pool's chunks, padded where MJX compiles
    obs = torch.where(traj.diverged.cpu()[:, None, None], torch.nan, traj.states.double().cpu())
    return obs.reshape(n, m, real.horizon + 1, -1)

"""The identifiability stage's helpers (diagnostics/identifiability.py): round 1's local sensitivity simulations
(the task's nominal parameters, the summaries of one set of action sequences and initial states at points around
them), and what the stage's findings are said as in the log."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch

from ...diagnostics.identifiability import STEP
from ...policies import OpenLoopPolicy, RandomPolicy
from ...sim.trajectories import Trajectories

log = logging.getLogger(__name__)


def nominal_point(spec, prior_std: torch.Tensor) -> torch.Tensor:
    """The task's nominal parameters in units of the prior's standard deviation, kept a step inside the box."""
    std = prior_std.double()
    low, high = torch.as_tensor(spec.low) + STEP * std, torch.as_tensor(spec.high) - STEP * std
    return torch.maximum(torch.minimum(torch.as_tensor(spec.nominal, dtype=torch.float64), high), low) / std


def summaries_at(points: torch.Tensor, *, task, sims, policy, prior_std: torch.Tensor, num: int, horizon: int,
                 seed: int, summarize: Callable[[Trajectories], torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """`num` action sequences and initial states (the collect policy's where it acts open loop, uniform random
    actions otherwise), the same at every point of points [K, D] (parameters in units of the prior's standard
    deviation): (summaries [K, num, F], kept [num])."""
    start = None
    if policy.plan is not None:
        policy, start = policy.plan(num)
    actions = (policy.actions if isinstance(policy, OpenLoopPolicy) else
               (policy if policy.open_loop_actions is not None else RandomPolicy(task.action_dim, seed))
               .open_loop_actions(num, horizon))[:, :horizon]
    if start is None:
        start = task.reset_state(np.random.default_rng(seed), num)
    k = len(points)
    theta = points * prior_std.double()
    traj = sims.rollout(theta.repeat_interleave(num, 0), OpenLoopPolicy(actions.repeat(k, 1, 1)), horizon, seed,
                        state={f: np.tile(v, (k,) + (1,) * (v.ndim - 1)) for f, v in start.items()})
    x = summarize(traj).double().reshape(k, num, -1)
    kept = ~traj.diverged.cpu().reshape(k, num).any(0) & torch.isfinite(x).all(-1).all(0)
    return x, kept


def log_findings(round_index: int, report: dict) -> None:
    """The linear read's trade-offs; the local sensitivity's parameters that move nothing or act alike."""
    for entry in report["trade_offs"]:
        log.info("round %d: %s and %s are told apart only in part (held-out prediction errors correlate %+.2f)",
                 round_index, *entry["pair"], entry["correlation"])
    local = report["local"]
    if local is None:
        return
    if local["no_effect"]:
        log.warning("round %d: %s move no summary at the nominal parameters (local sensitivity): the data cannot "
                    "identify them, and their posterior stays at the prior", round_index, ", ".join(local["no_effect"]))
    for entry in local["collinear"]:
        log.warning("round %d: %s and %s act alike at the nominal parameters (collinearity index %.0f): the data pin "
                    "down a combination of them", round_index, *entry["pair"], entry["index"])

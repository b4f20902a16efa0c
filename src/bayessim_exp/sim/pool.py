"""Long-lived simulators of a run, one per batch size, and chunked rollouts over many parameter sets.

A simulator is built once per size and reused by every stage and round. A collect of 10,000
simulations in chunks of 4,096 builds two, 4,096 and 1,808, where sizes cost nothing (native); where
each size is a compilation (MJX), the last chunk runs in the 4,096-slot simulator, filled up with
copies of its first row whose results are dropped (`Simulator.pads`; a batch below sim.native_below
runs on native MuJoCo in a simulator of its own size).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch

from ..policies import Policy
from ..tasks.base import Task
from .base import Simulator
from .integrators import varies
from .trajectories import Trajectories


class SimulatorPool:
    """`integrators`: MuJoCo integrators every simulator's slots alternate between (sim/integrators.py); empty:
    the model's own."""

    def __init__(self, make: Callable[[Task, int], Simulator], task: Task, chunk: int,
                 integrators: Sequence[str] = ()):
        if chunk < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk}")
        self.make, self.task, self.chunk = make, task, chunk
        self.integrators = tuple(integrators)
        self._sims: dict[int, Simulator] = {}

    def alternating(self, integrators: Sequence[str]) -> SimulatorPool:
        """A pool of simulators of its own whose slots alternate between `integrators`; this pool where they are
        the model's own integrator alone."""
        return SimulatorPool(self.make, self.task, self.chunk, integrators) if varies(integrators) else self

    def get(self, num_envs: int) -> Simulator:
        if num_envs not in self._sims:
            sim = self.make(self.task, num_envs)
            if self.integrators:
                sim.alternate_integrators(self.integrators)
            self._sims[num_envs] = sim
        return self._sims[num_envs]

    def rollout(self, params: torch.Tensor | np.ndarray, policy: Policy, horizon: int, seed: int,
                progress: bool = False, state: dict[str, np.ndarray] | None = None) -> Trajectories:
        """Trajectories for every row of params [N, D], simulated `chunk` slots at a time; chunk k resets
        with a seed derived from (seed, k). `state` (initial states [N, ...]) replaces the reset draw. A
        policy's `plan` (policies.ReplayPolicy) gives each row's actions and initial state; its `select` cuts
        it into chunks with the rows (policies.OpenLoopPolicy acts row by row)."""
        params = np.asarray(params, dtype=np.float64)
        if policy.plan is not None:
            policy, planned = policy.plan(len(params))
            state = planned if state is None else state
        seeds = np.random.SeedSequence(seed).generate_state(max(1, -(-len(params) // self.chunk)))
        parts = []
        for k, start in enumerate(range(0, len(params), self.chunk)):
            rows = slice(start, start + self.chunk)
            block = params[rows]
            part_state = None if state is None else {f: v[rows] for f, v in state.items()}
            part_policy = policy.select(rows)
            n, full = len(block), self._sims.get(self.chunk)
            if n < self.chunk and full is not None and full.pads(n):
                pad = self.chunk - n
                part_state = None if part_state is None else {f: _fill(np.asarray(v), pad) for f, v in part_state.items()}
                part_policy = part_policy.select(torch.as_tensor(_fill(np.arange(n), pad)))
                traj = full.rollout(_fill(block, pad), part_policy, horizon, int(seeds[k]), progress, part_state)
                parts.append(traj.select(slice(0, n)))
            else:
                parts.append(self.get(n).rollout(block, part_policy, horizon, int(seeds[k]), progress, part_state))
        return Trajectories.cat(parts)


def _fill(rows: np.ndarray, pad: int) -> np.ndarray:
    """rows followed by `pad` copies of the first row."""
    return np.concatenate([rows, np.repeat(rows[:1], pad, 0)])

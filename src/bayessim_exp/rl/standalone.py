"""The RL stages outside the pipeline: rounds whose posterior you hand in, outputs kept in memory.

    ctx = StandaloneRounds(task, sims, posterior=api.load_run(run_dir).posterior(), seed=0)
    component = registry.build("rl", cfg.rl, task=task, device="cpu")
    for stage in component.stages():
        ctx.run(stage)
    component.record(ctx)

Used by scripts/rl_posterior_vs_prior.py, benchmarks/rl.py and the tests; stage seeds follow the
pipeline's rule (run seed, round, stage name).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..sim.pool import SimulatorPool
from ..tasks.base import Task


def stage_seed(seed: int, round_index: int, stage: str) -> int:
    return int(np.random.SeedSequence([seed, round_index, *stage.encode()]).generate_state(1)[0])


class StandaloneRounds:
    """A RoundContext (rl/component.py) over fixed distributions; `next_round()` starts a new round."""

    def __init__(self, task: Task, sims: SimulatorPool, prior: Any, posterior: Any = None, seed: int = 0,
                 real_params: np.ndarray | None = None, tb: Any = None):
        self.task, self.sims, self.prior, self._posterior = task, sims, prior, posterior
        self.run_seed, self.tb = seed, tb
        self.real_params = task.real_values if real_params is None else np.asarray(real_params, dtype=np.float64)
        self.round, self.seed = 1, 0
        self.outputs: dict[tuple[int, str], dict] = {}

    def posterior(self) -> Any:
        if self._posterior is None:
            raise ValueError("no posterior was given to StandaloneRounds")
        return self._posterior

    def output(self, stage: str, round: int | None = None) -> dict | None:
        return self.outputs.get((self.round if round is None else round, stage))

    def run(self, stage) -> dict:
        """Run a StageSpec in the current round (skipped when its output is there) and keep its output."""
        key = (self.round, stage.name)
        if key not in self.outputs:
            self.seed = stage_seed(self.run_seed, self.round, stage.name)
            self.outputs[key] = stage.run(self)
        return self.outputs[key]

    def next_round(self) -> None:
        self.round += 1

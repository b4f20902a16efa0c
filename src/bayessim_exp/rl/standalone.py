"""The RL stages outside the pipeline, on a distribution you hand in (a saved posterior, the prior).

    comp = build_components(cfg, check_run_config(cfg))          # cfg with rl=ppo
    rounds = StandaloneRounds(comp, api.load_run(run_dir).posterior(), "outputs/ppo_on_saved_posterior")
    rounds.run_round(1)
    comp.rl.record(rounds.context(1))

Artifacts go to `out_dir` as in a pipeline run (round_NNN/<stage>.pt, skipped when there), and stages
are seeded by name exactly as there. Used by scripts/rl_posterior_vs_prior.py and the tests.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..artifacts import RunDir
from ..stages import RoundContext, run_stage


class GivenDistribution:
    """Stands in for the inference method: every round's distribution is the one handed in."""

    def __init__(self, distribution: Any):
        self.distribution = distribution

    def posterior(self, ctx: RoundContext) -> Any:
        return self.distribution


class StandaloneRounds:
    def __init__(self, comp, distribution: Any, out_dir: str | Path, tb: Any = None):
        if comp.rl is None:
            raise ValueError("the components were built with rl=none")
        comp.method = GivenDistribution(distribution)
        self.comp, self.run_dir, self.tb = comp, RunDir(out_dir), tb

    def context(self, round_index: int) -> RoundContext:
        return RoundContext(self.comp, self.run_dir, round_index, self.comp.rc.seed, self.tb)

    def run_round(self, round_index: int) -> RoundContext:
        """Run the RL component's stages of one round (those not already saved) and return its context."""
        ctx = self.context(round_index)
        for stage in self.comp.rl.stages():
            run_stage(ctx, stage)
        return ctx

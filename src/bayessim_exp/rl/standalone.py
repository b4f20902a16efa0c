"""The RL stages outside the pipeline, on a distribution you hand in (a saved posterior, the prior).

    cfg = api.compose(["rl=ppo"])
    comp = build_components(cfg, check_run_config(cfg))
    rounds = StandaloneRounds(cfg, comp, api.load_run(run_dir).posterior(), "outputs/ppo_on_saved_posterior")
    rounds.rl.record(rounds.run_round(1))

Artifacts go to `out_dir` as in a pipeline run (round_NNN/<stage>.pt, skipped when there), and stages
are seeded by name exactly as there. Used by scripts/rl_posterior_vs_prior.py and the tests.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from omegaconf import DictConfig

from ..artifacts import RunDir
from ..components import Components, build_rl
from ..distributions.base import ParameterDistribution
from ..logging.tensorboard import NO_TENSORBOARD
from ..stages import RoundContext, run_stage
from .none import NoRL

if TYPE_CHECKING:
    from ..logging.tensorboard import NullTensorBoard, TensorBoardLogger


class StandaloneRounds:
    def __init__(self, cfg: DictConfig, comp: Components, distribution: ParameterDistribution, out_dir: str | Path,
                 tb: TensorBoardLogger | NullTensorBoard = NO_TENSORBOARD):
        """The RL component of `cfg` (built from `comp`), training on `distribution` every round."""
        self.rl = build_rl(cfg, comp, lambda ctx: distribution)
        if isinstance(self.rl, NoRL):
            raise ValueError("the config has rl=none: there are no RL stages to run")
        self.seed, self.run_dir, self.tb = comp.rc.seed, RunDir(out_dir), tb

    def context(self, round_index: int) -> RoundContext:
        return RoundContext(self.run_dir, round_index, self.seed, self.tb)

    def run_round(self, round_index: int) -> RoundContext:
        """Run the RL component's stages of one round (those not already saved) and return its context."""
        ctx = self.context(round_index)
        for stage in self.rl.stages():
            run_stage(ctx, stage)
        return ctx

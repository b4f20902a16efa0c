"""SimOpt as an inference method (`method=simopt`): one `search` stage per round.

The round starts from the previous round's Gaussian (round 1: N(prior mean, prior variance)), runs
`updates` REPS updates against every real trajectory recorded so far, and hands out the final Gaussian
truncated to the prior's box: scored, plotted and used for domain randomization like a posterior. Each
update draws collect.trajectories / updates parameter samples, so a round simulates as many parameter
sets as a BayesSim round; each is rolled out from every real trajectory's start.
"""

from __future__ import annotations

import numpy as np
import torch

from ...distributions.base import ParameterDistribution
from ...distributions.mixture import GaussianMixture, TruncatedMixture
from ...errors import ConfigError, PosteriorError
from ...stages import RoundContext, Stage
from ..base import InferenceMethod, MethodInputs, real_trajectories
from .discrepancy import Discrepancy
from .reps import Gaussian
from .rollouts import simulate_like_real
from .search import SimOptConfig, initial_gaussian, search


class SimOpt(InferenceMethod):
    def __init__(self, cfg: SimOptConfig, inputs: MethodInputs):
        self.cfg, self.inputs = cfg, inputs
        self.samples = inputs.rc.collect.trajectories // cfg.updates
        if self.samples < 2:
            raise ConfigError(f"method=simopt: collect.trajectories={inputs.rc.collect.trajectories} over "
                              f"{cfg.updates} updates leaves fewer than 2 parameter samples per update")
        self.low, self.high = inputs.prior.low.double(), inputs.prior.high.double()

    def stages(self) -> list[Stage]:
        return [Stage("search", self.search, inputs=("real",))]

    def start(self, ctx: RoundContext) -> Gaussian:
        if ctx.round == 1:
            return initial_gaussian(self.inputs.prior.mean, self.inputs.prior.stddev, self.low, self.high, self.cfg.min_std)
        previous = ctx.output("search", ctx.round - 1)
        return Gaussian(previous["mean"], previous["cov"])

    def proposal(self, ctx: RoundContext) -> ParameterDistribution:
        """What the round starts from (its search samples the untruncated Gaussian, see search.py)."""
        return self._truncated(self.start(ctx), ctx.seed, ctx.round)

    def search(self, ctx: RoundContext) -> dict:
        real = real_trajectories(ctx)
        discrepancy = Discrepancy(self.cfg.discrepancy, self.inputs.task.obs_names, real.states)
        policy = self.inputs.policy(ctx.seed, ctx)
        seeds = iter(np.random.SeedSequence(ctx.seed).generate_state(self.cfg.updates).tolist())

        def cost(theta: torch.Tensor) -> torch.Tensor:
            return discrepancy(simulate_like_real(self.inputs.sims, theta, real, policy, self.cfg.rollout, next(seeds)))

        gaussians, history = search(self.start(ctx), cost, self.cfg, self.samples, self.low, self.high,
                                    torch.Generator().manual_seed(ctx.seed))
        final = gaussians[-1]
        return {"mean": final.mean, "cov": final.cov, "history": history, "real_trajectories": real.num,
                "posterior": self._truncated(final, ctx.seed, ctx.round)}

    def _truncated(self, g: Gaussian, seed: int, round_index: int) -> ParameterDistribution:
        try:
            return TruncatedMixture(GaussianMixture(torch.zeros(1), g.mean[None], g.cov[None]), self.low, self.high,
                                    seed=seed)
        except ValueError as exc:
            raise PosteriorError(f"round {round_index}: SimOpt's Gaussian: {exc}") from exc

    def posterior(self, ctx: RoundContext) -> ParameterDistribution:
        return searched(ctx, self.inputs.prior)

    def record(self, ctx: RoundContext) -> dict:
        out = ctx.output("search")
        history = out["history"]
        return {
            "sim_trajectories": self.samples * self.cfg.updates * out["real_trajectories"],
            "diverged": sum(h["diverged"] for h in history),
            "proposal": "simopt",
            "simopt_updates": history,
        }


def simopt(cfg: SimOptConfig, inputs: MethodInputs) -> SimOpt:
    return SimOpt(cfg, inputs)


def searched(ctx: RoundContext, prior: ParameterDistribution) -> ParameterDistribution:
    """The round's final Gaussian, truncated to the prior's box, from its search artifact (registry: posterior)."""
    return ctx.output("search")["posterior"]

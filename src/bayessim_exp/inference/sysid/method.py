"""MuJoCo's system identification as an inference method (`method=sysid`): one `fit` stage per round.

The round fits the task's parameters (the ParamSpec BayesSim infers: same names, box and operations, written by
sim/params.py) by least squares of every real trajectory recorded so far against its replay in simulation, from its
recorded initial state (Task.state_from_observation) under its recorded actions, with mujoco.sysid's optimiser
(fit.py) from several starts (starts.py). It hands out a Gaussian around the estimate (laplace.py) restricted to the
prior's box: scored, plotted and used for domain randomization like a posterior; where even the best fit leaves
residuals about as large as the observations' spread (method.max_noise_std), the round hands on the prior instead.
Round 1 starts at the prior's mean, later rounds at the previous round's estimate, each also from the best of a
screen of prior draws; each round fits all real data again, so the rounds do not multiply their information.
"""

from __future__ import annotations

import logging
import math

import torch

from ...distributions.base import ParameterDistribution
from ...distributions.mixture import GaussianMixture, TruncatedMixture
from ...errors import ConfigError, PosteriorError
from ...stages import RoundContext, Stage
from ...tasks.base import Task
from ..base import InferenceMethod, MethodInputs, real_trajectories
from .fit import INTERVAL_ALPHA, SysidConfig, interval_quantile, require_sysid
from .laplace import laplace_gaussian
from .residual import ReplayResidual
from .starts import best_fit, start_points

log = logging.getLogger(__name__)


class Sysid(InferenceMethod):
    def __init__(self, cfg: SysidConfig, inputs: MethodInputs):
        require_sysid()
        task = inputs.task
        if type(task).state_from_observation is Task.state_from_observation:
            raise ConfigError(f"method=sysid replays the real trajectories from their recorded initial states, and task "
                              f"{task.name} cannot map an observation to a simulator state "
                              "(Task.state_from_observation); use method=bayessim or method=simopt")
        self.cfg, self.inputs = cfg, inputs
        self.low, self.high = inputs.prior.low.double(), inputs.prior.high.double()

    def stages(self) -> list[Stage]:
        return [Stage("fit", self.fit, inputs=("real",))]

    def proposal(self, ctx: RoundContext) -> ParameterDistribution:
        """What the round starts from: the prior, then the previous round's distribution (sysid draws nothing from it)."""
        return self.inputs.prior if ctx.round == 1 else ctx.output("fit", ctx.round - 1)["posterior"]

    def fit(self, ctx: RoundContext) -> dict:
        real = real_trajectories(ctx)
        spec = self.inputs.task.spec
        residual = ReplayResidual(self.inputs.sims, real, spec.low, spec.high, self.cfg.observed)
        if ctx.round == 1:
            start = ((self.inputs.prior.mean.double() - self.low) / (self.high - self.low)).numpy()
        else:
            start = ctx.output("fit", ctx.round - 1)["estimate_unit"]
        starts = start_points(residual, start, self.inputs.prior, self.cfg, torch.Generator().manual_seed(ctx.seed))
        result = best_fit(residual, spec.names, starts, self.cfg)
        gaussian = laplace_gaussian(result, self.inputs.prior.mean, self.inputs.prior.stddev, self.low, self.high,
                                    self.cfg.min_noise_std, self.cfg.identified_below)
        # residuals about as large as the observations' spread: no start reached parameters that explain the data
        # (or the model cannot), and a Gaussian around this estimate would be confidently wrong
        failed = math.sqrt(result.noise_var) > self.cfg.max_noise_std
        if failed:
            log.warning("round %d: sysid's best fit leaves residuals of %.3g of the observations' spread (method."
                        "max_noise_std=%g); the round hands on the prior", ctx.round, math.sqrt(result.noise_var),
                        self.cfg.max_noise_std)
            posterior = self.inputs.prior
        else:
            try:
                posterior = TruncatedMixture(GaussianMixture(torch.zeros(1), gaussian.mean[None], gaussian.cov[None]),
                                             self.low, self.high, seed=ctx.seed)
            except ValueError as exc:
                raise PosteriorError(f"round {ctx.round}: sysid's Gaussian: {exc}") from exc
        return {
            "estimate_unit": result.estimate, "estimate": residual.theta(result.estimate),
            "data_std": gaussian.data_std, "identified": gaussian.identified,
            "interval_quantile": interval_quantile(*result.jacobian.shape), "objectives": result.objectives,
            "noise_std": math.sqrt(result.noise_var), "noise_std_used": gaussian.noise_std, "failed": failed,
            "simulations": residual.simulations, "diverged": residual.diverged, "real_trajectories": real.num,
            "posterior": posterior,
        }

    def posterior(self, ctx: RoundContext) -> ParameterDistribution:
        return fitted(ctx, self.inputs.prior)

    def handed_on_round(self, ctx: RoundContext) -> int:
        return 0 if ctx.output("fit")["failed"] else ctx.round

    def record(self, ctx: RoundContext) -> dict:
        out = ctx.output("fit")
        names = self.inputs.task.spec.names
        # sysid's confidence intervals at the noise used; None: not identifiable from the data
        half = [float(v) if math.isfinite(v) else None for v in (out["interval_quantile"] * out["data_std"]).tolist()]
        return {
            "sim_trajectories": int(out["simulations"]),
            "diverged": int(out["diverged"]),
            "proposal": "sysid",
            "sysid": {
                "estimate": dict(zip(names, map(float, out["estimate"]))),
                f"interval_{round(100 * (1 - INTERVAL_ALPHA))}": dict(zip(names, half)),
                "identified": dict(zip(names, map(bool, out["identified"].tolist()))),
                "iterations": len(out["objectives"]) - 1,
                "objective_start": out["objectives"][0], "objective_final": out["objectives"][-1],
                "noise_std": out["noise_std"], "noise_std_used": out["noise_std_used"],
                "failed": bool(out["failed"]),  # the round handed on the prior (method.max_noise_std)
            },
        }


def sysid(cfg: SysidConfig, inputs: MethodInputs) -> Sysid:
    return Sysid(cfg, inputs)


def fitted(ctx: RoundContext, prior: ParameterDistribution) -> ParameterDistribution:
    """The round's Gaussian around its estimate (or the prior it handed on), from its fit artifact (registry:
    posterior)."""
    return ctx.output("fit")["posterior"]

"""BayesSim (Ramos et al. 2019) as an inference method: simulate from a proposal, summarize, fit
q(theta | x), condition on every real summary with the proposal's correction.

Stages of a round: collect (parameters from the proposal, trajectories under the collect policy)
-> summarize -> identifiability (which parameters the summaries can pin down, diagnostics/identifiability.py)
-> fit (the posterior model, its spread calibrated and its coverage and gain measured on the round's own
held-out simulations) -> condition (the posterior given all real trajectories,
docs/statistics.md, widened until the real trajectories lie among its replays where the task can
replay them) -> model_check (predictive checks, the mismatch verdict) -> guard (what the round hands
on: its posterior, or on a failed check the last one that passed, method.on_guard).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable

import numpy as np
import torch

from ...diagnostics.coverage import expected_coverage, held_out_gain
from ...diagnostics.extrapolation import inputs_outside
from ...diagnostics.guard import ACTIONS, check_posterior
from ...diagnostics.identifiability import STEP, linear_read, sensitivity
from ...diagnostics.local_coverage import local_coverage
from ...diagnostics.mismatch import mismatch_report, summaries_outside
from ...diagnostics.predictive import predictive_distances
from ...diagnostics.replay import replay
from ...diagnostics.replayed_check import replayed_check
from ...distributions.base import ParameterDistribution
from ...distributions.hpd import own_level
from ...distributions.probit import ProbitPosterior, ProbitTransform, standard_normal_prior
from ...distributions.truncated_prior import TruncatedPrior
from ...errors import ConfigError, PosteriorError
from ...models.base import column_scale
from ...policies import OpenLoopPolicy, RandomPolicy
from ...sim.trajectories import Trajectories
from ...stages import RoundContext, Stage, stage_seed
from ..base import InferenceMethod, MethodInputs, real_trajectories
from .combination import COMBINATIONS
from .condition import condition, tempered_product
from .proposals import moment_matched
from .replay_tempering import temper_to_replays
from .set_calibration import product_temperature

log = logging.getLogger(__name__)

# proposal -> how rounds after the first draw their parameters (docs/statistics.md):
#   prior      always the prior; every round's simulations train the model
#   posterior  the previous posterior itself (SNPE-A; closed form only for one-component mixtures)
#   gaussian   the previous posterior moment-matched to one Gaussian (SNPE-A in closed form for mixtures)
#   truncated  the prior restricted to the previous posterior's 99.9 % HPD region (TSNPE, no correction)
PROPOSALS = ("prior", "posterior", "gaussian", "truncated")
# probit: fitted on the prior's CDFs mapped through the normal quantile (posteriors stay on the box);
# box: in parameter units; auto: probit where the prior allows it (independent, on a box), else box
PARAMETER_SPACES = ("auto", "probit", "box")
# SNPE-A needs the model trained on draws from a single proposal: the current round's simulations only
_SINGLE_ROUND_PROPOSALS = ("posterior", "gaussian")


@dataclasses.dataclass
class BayesSimConfig:
    proposal: str  # prior | posterior | gaussian | truncated
    finetune: bool  # continue training the previous round's model (false: re-initialise)
    max_components: int  # mixture components kept when combining several real trajectories
    parameter_space: str  # auto | probit | box: what the model is fitted in (distributions/probit.py)
    combination: str  # several real trajectories: dispersion | product (combination.py)
    replay_tempering: bool  # widen the posterior until the real trajectories lie among its replays
    on_guard: str  # a round the guard flags: warn | fallback | stop (diagnostics/guard.py)

    def validate(self) -> None:
        if self.parameter_space not in PARAMETER_SPACES:
            raise ConfigError(f"parameter_space={self.parameter_space!r} not allowed; allowed: {', '.join(PARAMETER_SPACES)}")
        if self.proposal not in PROPOSALS:
            raise ConfigError(f"proposal={self.proposal!r} not allowed; allowed: {', '.join(PROPOSALS)}")
        if self.combination not in COMBINATIONS:
            raise ConfigError(f"combination={self.combination!r} not allowed; allowed: {', '.join(COMBINATIONS)}")
        if self.on_guard not in ACTIONS:
            raise ConfigError(f"on_guard={self.on_guard!r} not allowed; allowed: {', '.join(ACTIONS)}")
        if self.max_components < 1:
            raise ConfigError(f"max_components must be >= 1, got {self.max_components}")


class BayesSim(InferenceMethod):
    def __init__(self, cfg: BayesSimConfig, inputs: MethodInputs):
        self.cfg, self.inputs = cfg, inputs
        self._proposals: dict[int, ParameterDistribution | None] = {}
        self.probit = None if cfg.parameter_space == "box" else _probit_transform(cfg.parameter_space, inputs.prior)

    def stages(self) -> list[Stage]:
        return [
            Stage("collect", self.collect, transient=not self.inputs.rc.collect.keep_trajectories),
            Stage("summarize", self.summarize, inputs=("collect",)),
            Stage("identifiability", self.identifiability, inputs=("summarize",)),
            Stage("fit", self.fit, inputs=("summarize",)),
            Stage("condition", self.condition, inputs=("real", "fit")),
            Stage("model_check", self.model_check, inputs=("real", "summarize", "fit", "condition")),
            Stage("guard", self.guard, inputs=("fit", "condition", "model_check")),
        ]

    # proposals -----------------------------------------------------------------------
    def proposal(self, ctx: RoundContext) -> ParameterDistribution:
        """The distribution round r draws its parameters from (see PROPOSALS)."""
        return self.inputs.prior if self.proposal_name(ctx) == "prior" else self._proposals[ctx.round]

    def proposal_name(self, ctx: RoundContext) -> str:
        """The proposal round r really uses: `truncated` falls back to the prior when the previous round's
        distribution is the prior (the guard's fallback) or its region is too small a share of it to
        sample (many parameters)."""
        r = ctx.round
        if r == 1 or self.cfg.proposal == "prior":
            return "prior"
        if r not in self._proposals:
            previous = self._handed_on(ctx, r - 1)
            seed = stage_seed(ctx.run_seed, r, "proposal")  # fixed per round, whichever stage asks first
            if previous is self.inputs.prior:
                self._proposals[r] = None
            elif self.cfg.proposal == "truncated":
                try:
                    self._proposals[r] = TruncatedPrior(self.inputs.prior, previous, seed=seed)
                except ValueError as exc:
                    log.warning("round %d: %s; simulating from the prior instead", r, exc)
                    self._proposals[r] = None
            elif self.cfg.proposal == "gaussian" and self.probit is not None:
                self._proposals[r] = ProbitPosterior(moment_matched(previous.inner, seed=seed), self.probit)
            elif self.cfg.proposal == "gaussian":
                self._proposals[r] = moment_matched(previous, self.inputs.prior.low, self.inputs.prior.high, seed=seed)
            else:
                self._proposals[r] = previous
        return "prior" if self._proposals[r] is None else self.cfg.proposal

    # stages --------------------------------------------------------------------------
    def collect(self, ctx: RoundContext) -> dict:
        """The round's simulations under the collect policy. Where that policy replays the real trajectories with
        noise, the last rows (twice the held-out share) replay them as they were executed: the pairs the spread is
        calibrated on and the held-out pairs, drawn like the real data (docs/statistics.md, 'Simulations driven
        like the real system')."""
        rc = self.inputs.rc
        theta = self.proposal(ctx).sample((rc.collect.trajectories,), generator=torch.Generator().manual_seed(ctx.seed))
        policy = self.inputs.policy(ctx.seed, ctx)
        exact = self._without_noise(policy)
        n_exact = 0 if exact is None else 2 * self._held_out_count(len(theta))
        cut = len(theta) - n_exact
        traj = self.inputs.sims.rollout(theta[:cut], policy, rc.collect.horizon, ctx.seed, rc.logging.progress)
        if n_exact:
            exact_seed = stage_seed(ctx.run_seed, ctx.round, "collect_exact")
            traj = Trajectories.cat([traj, self.inputs.sims.rollout(theta[cut:], exact, rc.collect.horizon, exact_seed)])
        return {"theta": theta.float(), "traj": traj.state_dict(), "exact": torch.arange(len(theta)) >= cut}

    @staticmethod
    def _without_noise(policy):
        """The collect policy as the real data were driven (policies.ReplayPolicy.without_noise), or None."""
        return policy.without_noise() if hasattr(policy, "without_noise") else None

    def summarize(self, ctx: RoundContext) -> dict:
        collected = ctx.output("collect")
        traj = Trajectories(**collected["traj"]).to(self.inputs.device)
        keep = ~traj.diverged
        x = self.inputs.summarizer(traj.select(keep)).cpu()
        finite = torch.isfinite(x).all(1)
        theta = collected["theta"][keep.cpu()][finite]
        exact = collected.get("exact", torch.zeros(len(keep), dtype=torch.bool))[keep.cpu()][finite]
        return {"theta": theta, "x": x[finite], "exact": exact,
                "diverged": int((~keep).sum()) + int((~finite).sum())}

    def identifiability(self, ctx: RoundContext) -> dict:
        """What the round's summaries can say about each parameter (diagnostics/identifiability.py): the linear read
        of its training simulations, and in round 1 the local sensitivity at the nominal parameters, whose
        parameters that move nothing are said before any fit."""
        theta, x, _, _ = self._split(ctx.output("summarize"))
        d, names = self.inputs.rc.diagnostics, self.inputs.task.spec.names
        report = {**linear_read(x.to(self.inputs.device), self._fitted_space(theta), names), "local": None}
        for entry in report["trade_offs"]:
            log.info("round %d: %s and %s are told apart only in part (held-out prediction errors correlate %+.2f)",
                     ctx.round, *entry["pair"], entry["correlation"])
        if d.sensitivity_sims and ctx.round == 1:
            report["local"] = local = sensitivity(lambda points: self._summaries_at(ctx, points), self._nominal(),
                                                  column_scale(x.double()), names)
            if local["no_effect"]:
                log.warning("round 1: %s move no summary at the nominal parameters (local sensitivity): the data "
                            "cannot identify them, and their posterior stays at the prior", ", ".join(local["no_effect"]))
            for entry in local["collinear"]:
                log.warning("round 1: %s and %s act alike at the nominal parameters (collinearity index %.0f): the data "
                            "pin down a combination of them", *entry["pair"], entry["index"])
        ctx.tb.identifiability(ctx.round, names, report)
        return report

    def _nominal(self) -> torch.Tensor:
        """The task's nominal parameters in units of the prior's standard deviation, kept a step inside the box."""
        spec, std = self.inputs.task.spec, self.inputs.prior.stddev.double()
        low, high = torch.as_tensor(spec.low) + STEP * std, torch.as_tensor(spec.high) - STEP * std
        return torch.maximum(torch.minimum(torch.as_tensor(spec.nominal, dtype=torch.float64), high), low) / std

    def _summaries_at(self, ctx: RoundContext, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """identifiability.sensitivity's simulations: `diagnostics.sensitivity_sims` action sequences and initial states
        (the collect policy's where it acts open loop, uniform random actions otherwise), the same at every point of
        points [K, D] (parameters in units of the prior's standard deviation): (summaries [K, M, F], kept [M])."""
        m, horizon = self.inputs.rc.diagnostics.sensitivity_sims, self.inputs.rc.collect.horizon
        policy, task = self.inputs.policy(ctx.seed, ctx), self.inputs.task
        start = None
        if hasattr(policy, "plan"):
            policy, start = policy.plan(m)
        actions = (policy.actions if isinstance(policy, OpenLoopPolicy) else
                   (policy if hasattr(policy, "open_loop_actions") else RandomPolicy(task.action_dim, ctx.seed))
                   .open_loop_actions(m, horizon))[:, :horizon]
        if start is None:
            start = task.reset_state(np.random.default_rng(ctx.seed), m)
        k = len(points)
        theta = points * self.inputs.prior.stddev.double()
        traj = self.inputs.sims.rollout(theta.repeat_interleave(m, 0), OpenLoopPolicy(actions.repeat(k, 1, 1)), horizon,
                                      ctx.seed, state={f: np.tile(v, (k,) + (1,) * (v.ndim - 1)) for f, v in start.items()})
        x = self._summaries(traj).double().reshape(k, m, -1)
        kept = ~traj.diverged.cpu().reshape(k, m).any(0) & torch.isfinite(x).all(-1).all(0)
        return x, kept

    def fit(self, ctx: RoundContext) -> dict:
        r = ctx.round
        data = [self._split(ctx.output("summarize", k)) for k in self._fitted_rounds(ctx)]
        theta, x = self._fitted_space(torch.cat([d[0] for d in data])), torch.cat([d[1] for d in data])
        model = self.inputs.model()
        if r > 1 and self.cfg.finetune:
            model.load_state_dict(ctx.output("fit", r - 1)["model"])
        # trained on the run's device (summaries are stored on the CPU; with device=cuda they are copied there)
        dev = self.inputs.device
        # the spread is calibrated on the latest round's pairs, drawn like the pairs the posterior is used on:
        # one factor per parameter fitted to rounds pooled from several proposals would fit the wide early ones
        latest = torch.zeros(len(theta), dtype=torch.bool)
        latest[len(theta) - len(data[-1][0]):] = True
        # simulations replayed as the real data were driven are kept for the calibration alone
        exact = torch.cat([self._exact_training_rows(ctx.output("summarize", k)) for k in self._fitted_rounds(ctx)])
        history = model.fit(theta.to(dev), x.to(dev), seed=ctx.seed, label=f"round {r}", calibration_rows=latest,
                            calibration_only=exact if bool((exact & latest).any()) else None)
        ctx.tb.losses(r, history)
        theta_val, x_val = data[-1][2], data[-1][3]
        d = self.inputs.rc.diagnostics
        if len(theta_val) == 0:
            return {"model": model.state_dict(), "history": history, "num_train": len(theta), "coverage": None,
                    "held_out": None}
        coverage = expected_coverage(model, self._fitted_space(theta_val), x_val, d.levels, d.coverage_samples,
                                     seed=ctx.seed)
        over_prior = held_out_gain(model, self._fitted_space(theta_val), x_val, self._fitted_prior())
        # log q - log p~ = (log q - log p) - (log p~ - log p), the same in parameter units and in probit space
        proposal_ratio = (self.proposal(ctx).log_prob(theta_val.double()) - self.inputs.prior.log_prob(theta_val.double()))
        held_out = {"count": len(theta_val), "gain": over_prior,
                    "gain_over_proposal": over_prior - float(proposal_ratio.mean())}
        return {"model": model.state_dict(), "history": history, "num_train": len(theta), "coverage": coverage,
                "held_out": held_out}

    def _fitted_rounds(self, ctx: RoundContext) -> range:
        """The rounds whose simulations the round's model is trained on."""
        return range(ctx.round if self.cfg.proposal in _SINGLE_ROUND_PROPOSALS else 1, ctx.round + 1)

    def _fitted_space(self, theta: torch.Tensor) -> torch.Tensor:
        return theta if self.probit is None else self.probit.to_probit(theta).float()

    def _fitted_prior(self) -> ParameterDistribution:
        return self.inputs.prior if self.probit is None else standard_normal_prior(self.probit.dim)

    def _held_out_count(self, n: int) -> int:
        return int(self.inputs.rc.diagnostics.held_out_fraction * n)

    def _split(self, summary: dict) -> tuple[torch.Tensor, ...]:
        """(theta, x) for training and (theta, x) held out for the coverage check (the last rows)."""
        cut = len(summary["theta"]) - self._held_out_count(len(summary["theta"]))
        return summary["theta"][:cut], summary["x"][:cut], summary["theta"][cut:], summary["x"][cut:]

    def _exact_training_rows(self, summary: dict) -> torch.Tensor:
        """[rows of _split's training part] bool: those replayed as the real data were driven (collect)."""
        n = len(summary["theta"])
        exact = summary.get("exact", torch.zeros(n, dtype=torch.bool))  # absent from rounds summarized before
        return exact[: n - self._held_out_count(n)]

    def _fitted_model(self, ctx: RoundContext):
        model = self.inputs.model()
        model.load_state_dict(ctx.output("fit")["model"])
        return model

    def condition(self, ctx: RoundContext) -> dict:
        model = self._fitted_model(ctx)
        real = real_trajectories(ctx)
        x_real = self._summaries(real)
        spreads = []
        product_tau, product_record = self._product_temperature(ctx, model, real.num)

        def condition_at(temperature: float):
            try:
                post, spread = condition(model, x_real, self.inputs.prior, self.cfg.max_components,
                                         proposal=self.proposal(ctx), seed=ctx.seed, probit=self.probit,
                                         combination=self.cfg.combination, temperature=product_tau * temperature)
            except ValueError as exc:
                raise PosteriorError(f"round {ctx.round}: {exc}") from exc
            spreads.append(spread)
            return post

        d = self.inputs.rc.diagnostics
        replayable = d.replay_sims > 0 and self.inputs.task.state_from_observation(
            real.states[:1, 0].double().cpu().numpy()) is not None
        if d.replay_sims and not replayable:
            log.info("round %d: replayed predictive check skipped: task %s cannot restart from an observation",
                     ctx.round, self.inputs.task.name)
        out = {"x_real": x_real, "temperature": 1.0, "replay_check": None, "unwidened_replay_check": None,
               "tempering": None, "product_temperature": product_record}
        if not replayable:
            out["posterior"] = condition_at(1.0)
        else:
            def check(posterior):
                return replayed_check(lambda theta, which: replay(self.inputs.sims, theta, real, which), real, posterior,
                                      self.inputs.prior, summarize=self._summaries, num=d.replay_sims, seed=ctx.seed,
                                      alpha=d.mismatch_alpha, max_distance_ratio=d.mismatch_distance_ratio)

            if self.cfg.replay_tempering:
                out["posterior"], first, result, out["temperature"], out["tempering"] = temper_to_replays(
                    condition_at, check, torch.diag(self.inputs.prior.stddev.double() ** 2))
            else:
                out["posterior"] = condition_at(1.0)
                first = result = check(out["posterior"])
            out["replay_check"], out["unwidened_replay_check"] = result.record(), first.record()
            ctx.tb.replays(ctx.round, result, list(self.inputs.task.obs_names))
        out["dispersion"] = None if spreads[-1] is None else spreads[-1].record()
        out["temperature"] *= product_tau
        return out

    def _product_temperature(self, ctx: RoundContext, model, n: int) -> tuple[float, dict | None]:
        """For products of n > 1 trajectories (the real ones; for the local check, those and one simulated): the
        temperature fitted on sets of n simulations at the round's held-out parameters (set_calibration.py);
        (1, None) for one trajectory or without sets."""
        count = min(self.inputs.rc.diagnostics.combination_sets, len(self._split(ctx.output("summarize"))[2]))
        if n < 2 or count == 0:
            return 1.0, None
        theta = self._split(ctx.output("summarize"))[2][:count].double()
        seed = stage_seed(ctx.run_seed, ctx.round, "product_temperature")  # its own stream, as the checks'
        kept, x = self._simulate(ctx, theta.repeat_interleave(n, 0), seed)
        ok = kept.reshape(count, n).all(1)
        theta, x = theta[ok], x.reshape(count, n, -1)[ok]

        draws = self.inputs.rc.diagnostics.coverage_samples
        products = [self._tempered_product(ctx, [model.conditional(x_i.float()) for x_i in x_set]) for x_set in x]

        def levels_at(temperature: float) -> torch.Tensor:
            generator = torch.Generator().manual_seed(seed)  # the same draws' stream at every temperature
            return torch.tensor([own_level(product(temperature), t, draws, generator)
                                 for product, t in zip(products, theta)], dtype=torch.float64)

        tau, record = product_temperature(levels_at, self.inputs.rc.diagnostics.levels)
        if tau < 1:
            log.info("round %d: products of %d trajectories widened to temperature %.3g (fitted on %d simulated sets)",
                     ctx.round, n, tau, len(theta))
        return tau, record

    def _tempered_product(self, ctx: RoundContext, conditionals: list) -> Callable[[float], ParameterDistribution]:
        """The posterior given trajectories' per-trajectory posteriors, combined as the product tempered to the
        temperature it is called with (their product computed once)."""
        return tempered_product(conditionals, self.inputs.prior, self.cfg.max_components, self.proposal(ctx), ctx.seed,
                                self.probit)

    def _simulate(self, ctx: RoundContext, theta: torch.Tensor, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        """One trajectory at each theta [K, D] under the collect policy, driven as the real data were where it replays
        them (collect): (kept [K]: neither diverged nor with a non-finite summary, summaries [K, F] in float64)."""
        policy = self.inputs.policy(seed, ctx)
        traj = self.inputs.sims.rollout(theta, self._without_noise(policy) or policy, self.inputs.rc.collect.horizon, seed)
        x = self._summaries(traj).double()
        return ~traj.diverged.cpu() & torch.isfinite(x).all(-1), x

    def _summaries(self, traj: Trajectories) -> torch.Tensor:
        return self.inputs.summarizer(traj.to(self.inputs.device)).cpu()

    def model_check(self, ctx: RoundContext) -> dict:
        """Can the simulator, at parameters the posterior allows, reproduce the real data? The summary
        predictive check and the mismatch verdict (diagnostics/mismatch.py) from the real summaries'
        place among the simulated ones, the replayed check (condition) and the dispersion. And does the model
        know the real data: do they lie among its training simulations, is it calibrated there (the guard reads
        `extrapolation` and `local_coverage`)?"""
        d, conditioned = self.inputs.rc.diagnostics, ctx.output("condition")
        _, x_train, _, x_held = self._split(ctx.output("summarize"))
        outside = summaries_outside(conditioned["x_real"], x_train, x_held)
        return {"predictive_distance": self._predictive(ctx, conditioned["posterior"], conditioned["x_real"]),
                "mismatch": mismatch_report(ctx.round, outside, conditioned["unwidened_replay_check"],
                                            conditioned["dispersion"], d.mismatch_alpha),
                "extrapolation": self._extrapolation(ctx, conditioned["x_real"]),
                "local_coverage": self._local_coverage(ctx, conditioned)}

    def _extrapolation(self, ctx: RoundContext, x_real: torch.Tensor) -> dict | None:
        """diagnostics/extrapolation.py: the real summaries among the training simulations, in the parameters a
        regression from the model's inputs predicts (None without held-out simulations or with
        `diagnostics.extrapolation_alpha` 0)."""
        alpha = self.inputs.rc.diagnostics.extrapolation_alpha
        data = [self._split(ctx.output("summarize", k)) for k in self._fitted_rounds(ctx)]
        if alpha == 0 or len(data[-1][3]) == 0:
            return None
        model = self._fitted_model(ctx)
        with torch.no_grad():
            train = torch.cat([model.inputs(x_train) for _, x_train, _, _ in data])
            theta = self._fitted_space(torch.cat([theta_train for theta_train, _, _, _ in data]))
            return inputs_outside(model.inputs(x_real.reshape(-1, x_real.shape[-1])), train, theta,
                                  model.inputs(data[-1][3]), alpha, seed=ctx.seed)

    def _local_coverage(self, ctx: RoundContext, conditioned: dict) -> dict | None:
        """diagnostics/local_coverage.py with `diagnostics.local_sets` draws. The n real trajectories and the
        simulated one are combined as product at the temperature fitted for products of n + 1 on the proposal's
        sets (_product_temperature), so the check finds what is wrong near the real data beyond what products
        get wrong on average (the handed-on posterior is widened for that already). No replay widening: the
        simulations have no model error."""
        d = self.inputs.rc.diagnostics
        if d.local_sets == 0:
            return None
        if conditioned["posterior"].effective_sample_size is not None:  # each draw's posterior would be sampled too
            log.info("round %d: coverage near the real data skipped: the posterior is an importance-sampling "
                     "estimate (no closed form)", ctx.round)
            return None
        model = self._fitted_model(ctx)
        x_real = conditioned["x_real"].reshape(-1, conditioned["x_real"].shape[-1])
        tau, _ = self._product_temperature(ctx, model, len(x_real) + 1)
        seed = stage_seed(ctx.run_seed, ctx.round, "local_coverage")

        def simulate(theta: torch.Tensor) -> tuple[torch.Tensor, list]:
            kept, x = self._simulate(ctx, theta, seed)
            return kept, [model.conditional(x_j.float()) for x_j in x[kept]]

        real = [model.conditional(x.float()) for x in x_real]
        return {**local_coverage(lambda conditionals: self._tempered_product(ctx, conditionals)(tau), real, simulate,
                                 d.local_sets, d.levels, d.coverage_samples, seed), "temperature": tau}

    def _predictive(self, ctx: RoundContext, posterior, x_real: torch.Tensor) -> dict | None:
        num = self.inputs.rc.diagnostics.predictive_sims
        if num == 0:
            return None

        def simulate_summaries(theta: torch.Tensor) -> torch.Tensor:
            traj = self.inputs.sims.rollout(theta, self.inputs.policy(ctx.seed, ctx), self.inputs.rc.collect.horizon,
                                          ctx.seed).to(self.inputs.device)
            x = self.inputs.summarizer(traj.select(~traj.diverged)).cpu()
            return x[torch.isfinite(x).all(1)]

        return predictive_distances(simulate_summaries, x_real, posterior, self.inputs.prior, num, ctx.seed)

    def guard(self, ctx: RoundContext) -> dict:
        """The guard's findings (diagnostics/guard.py) and what the round hands on to domain randomization
        and the next proposal: its own posterior, or with on_guard=fallback and a finding the distribution
        the previous round handed on (the prior before round 1)."""
        r, held_out, checked = ctx.round, ctx.output("fit")["held_out"] or {}, ctx.output("model_check")
        conditioned = ctx.output("condition")
        baseline = "prior" if self.proposal_name(ctx) == "prior" else f"round's proposal ({self.proposal_name(ctx)})"
        # real trajectories replayed, and the posterior widened by what the replays leave unexplained: that comparison
        # with simulations near the posterior stands in for the distance from the training ones (docs/statistics.md)
        widened_by_replays = self.cfg.replay_tempering and conditioned["replay_check"] is not None
        report = check_posterior(held_out.get("gain_over_proposal"), (ctx.output("fit")["coverage"] or {}).get("hpd"),
                                 held_out.get("count", 0), baseline, conditioned["posterior"].effective_sample_size,
                                 local=checked.get("local_coverage"),
                                 extrapolation=None if widened_by_replays else checked.get("extrapolation"))
        action = self.cfg.on_guard if report.failed else "warn" if report.warnings else "none"
        handed_on = self._handed_on_round(ctx, r - 1) if action == "fallback" else r
        for warning in report.warnings:
            log.warning("round %d: %s", r, warning)
        if action == "fallback":
            log.warning("round %d: the guard failed; domain randomization and the next proposal get %s instead "
                        "(method.on_guard=fallback)", r, _round_name(handed_on))
        return {**report.to_dict(), "action": action, "handed_on": handed_on}

    def _handed_on_round(self, ctx: RoundContext, r: int) -> int:
        """The round whose posterior round r handed on; 0: the prior."""
        return 0 if r == 0 else ctx.output("guard", r)["handed_on"]

    def _handed_on(self, ctx: RoundContext, r: int) -> ParameterDistribution:
        source = self._handed_on_round(ctx, r)
        return self.inputs.prior if source == 0 else ctx.output("condition", source)["posterior"]

    # results -------------------------------------------------------------------------
    def posterior(self, ctx: RoundContext) -> ParameterDistribution:
        return self._handed_on(ctx, ctx.round)

    def stop_reason(self, ctx: RoundContext) -> str | None:
        guard = ctx.output("guard")
        if guard["action"] != "stop":
            return None
        return f"round {ctx.round}: the guard failed (method.on_guard=stop): " + "; ".join(guard["warnings"])

    def record(self, ctx: RoundContext) -> dict:
        summary, fitted, conditioned, guard = (ctx.output(s) for s in ("summarize", "fit", "condition", "guard"))
        hist = fitted["history"]
        return {
            "sim_trajectories": self.inputs.rc.collect.trajectories,
            "train_set_size": fitted["num_train"],
            "diverged": summary["diverged"],
            "epochs": hist["epochs"],
            "train_loss": hist["train"][-1],
            "val_loss": hist["best_val"],
            "joint_spread": hist.get("joint_spread"),  # the common factor on the spread (models/spread.py)
            "proposal": self.proposal_name(ctx),
            "coverage": fitted["coverage"],
            "held_out": fitted["held_out"],
            "identifiability": {k: v for k, v in ctx.output("identifiability").items() if k != "seconds"},
            "guard": {**{k: guard[k] for k in ("ok", "failed", "warnings", "action")},
                      "handed_on": _round_name(guard["handed_on"])},
            "dispersion": conditioned["dispersion"],
            "temperature": conditioned["temperature"],
            "product_temperature": conditioned["product_temperature"],
            "replay_check": conditioned["replay_check"],
            **{k: v for k, v in ctx.output("model_check").items() if k != "seconds"},
        }


def _round_name(r: int) -> str:
    return "the prior" if r == 0 else f"round {r}'s posterior"


def _probit_transform(space: str, prior: ParameterDistribution) -> ProbitTransform | None:
    """parameter_space probit or auto: the transform, None where auto falls back to parameter units."""
    try:
        return ProbitTransform(prior)
    except ValueError as exc:
        if space == "auto":
            log.info("method.parameter_space=auto: %s; fitting in parameter units", exc)
            return None
        raise ConfigError(f"method.parameter_space=probit: {exc}; set method.parameter_space=box (or auto)") from None


def bayessim(cfg: BayesSimConfig, inputs: MethodInputs) -> BayesSim:
    return BayesSim(cfg, inputs)

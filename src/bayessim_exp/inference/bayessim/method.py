"""BayesSim (Ramos et al. 2019) as an inference method: simulate from a proposal, summarize, fit
q(theta | x), condition on every real summary with the proposal's correction.

Stages of a round: proposal (what the round draws its parameters from, proposals.py) -> collect (parameters
from the proposal, trajectories under the collect policy) -> summarize -> identifiability (which parameters the summaries can pin down, diagnostics/identifiability.py)
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
from typing import Any

import torch

from ...diagnostics.coverage import expected_coverage, held_out_gain
from ...diagnostics.guard import Action, check_posterior
from ...diagnostics.identifiability import linear_read, sensitivity
from ...diagnostics.mismatch import flag_outside, mismatch_report, summaries_outside
from ...diagnostics.predictive import predictive_distances
from ...diagnostics.replay import replay
from ...diagnostics.replayed_check import replayed_check
from ...distributions.base import ParameterDistribution
from ...distributions.mixture import GaussianMixture, TruncatedMixture
from ...distributions.probit import ProbitPosterior, standard_normal_prior
from ...errors import ConfigError, PosteriorError
from ...models.base import column_scale
from ...sim.integrators import check_names as check_integrators
from ...sim.trajectories import Trajectories
from ...stages import RoundContext, Stage, stage_seed
from ..base import InferenceMethod, MethodInputs, handed_on_name, real_trajectories
from .combination import Combination
from .condition import condition, tempered_product, tempered_products
from .escape import READS, Escape, read_at
from .handed_on import ProposalSource, handed_on, handed_on_round, posterior_of, proposal_source
from .identifiability_checks import log_findings, nominal_point, summaries_at
from .model_checks import coverage_near_real, extrapolation
from .parameter_space import ParameterSpace, probit_transform
from .proposals import ProposalInputs, proposal_named
from .replay_tempering import temper_to_replays
from .set_calibration import SetPosteriors, set_importance_draws, simulated_sets_temperature
from .simulate import predictive_summaries, simulate_as_driven
from .summary_error import Mode as SummaryErrorMode
from .summary_error import SummaryError
from .training_data import CalibrateOn, calibration_rows, exact_training_rows, held_out_count, split, summarized

log = logging.getLogger(__name__)


@dataclasses.dataclass
class BayesSimConfig:
    proposal: str  # prior | posterior | gaussian | truncated | a plugin's (proposals.py)
    finetune: bool  # continue training the previous round's model (false: re-initialise)
    max_components: int  # mixture components kept when combining several real trajectories
    parameter_space: ParameterSpace  # what the model is fitted in (distributions/probit.py)
    combination: Combination  # of several real trajectories (combination.py)
    replay_tempering: bool  # widen the posterior until the real trajectories lie among its replays
    on_guard: Action  # what a round the guard flags hands on (diagnostics/guard.py)
    escape: Escape  # where a round whose real data lie outside its simulations proposes the next (escape.py)
    escape_rounds: int  # rounds added past `rounds` while an escape is under way (BayesSim.added_round)
    importance_draws: int  # base draws of a posterior without a closed form (flows; correction.py)
    integrators: Any  # auto or a list: the integrators inputs.sims alternate between (components.build_method)
    summary_error: SummaryErrorMode  # noise on simulated summaries where the replays leave features unexplained
    calibrate_on: CalibrateOn  # the pooled rounds' validation pairs the model's spread is calibrated on

    def validate(self) -> None:
        proposal_named(self.proposal)
        if self.escape_rounds < 0:
            raise ConfigError(f"escape_rounds must be >= 0, got {self.escape_rounds}")
        if self.max_components < 1:
            raise ConfigError(f"max_components must be >= 1, got {self.max_components}")
        check_integrators(self.integrators)
        if self.importance_draws < 1000:
            raise ConfigError(f"importance_draws must be >= 1000 (the importance-sampled posterior's base draws), "
                              f"got {self.importance_draws}")


class BayesSim(InferenceMethod):
    def __init__(self, cfg: BayesSimConfig, inputs: MethodInputs):
        self.cfg, self.inputs = cfg, inputs
        self.proposer = proposal_named(cfg.proposal)
        self.probit = None if cfg.parameter_space == "box" else probit_transform(cfg.parameter_space, inputs.prior)

    def stages(self) -> list[Stage]:
        return [
            Stage("proposal", self.propose),
            Stage("collect", self.collect, inputs=("proposal",), transient=not self.inputs.rc.collect.keep_trajectories),
            Stage("summarize", self.summarize, inputs=("collect",)),
            Stage("identifiability", self.identifiability, inputs=("summarize",)),
            Stage("fit", self.fit, inputs=("proposal", "summarize")),
            Stage("condition", self.condition, inputs=("real", "proposal", "fit")),
            Stage("model_check", self.model_check, inputs=("real", "proposal", "summarize", "fit", "condition")),
            Stage("guard", self.guard, inputs=("proposal", "summarize", "fit", "condition", "model_check")),
        ]

    # stages --------------------------------------------------------------------------
    def propose(self, ctx: RoundContext) -> dict:
        """Round r's proposal, built from the posterior round r - 1's guard chose for it (proposals.py): its name as
        results.json records it ('prior' where the round simulates from the prior), the distribution (None for the
        prior) and the round whose posterior it was built from (0: the prior)."""
        r, proposal = ctx.round, None
        source = proposal_source(ctx, r - 1)
        if r > 1:
            origin = (self._read_distribution(ctx.output("guard", source.round)["read"]) if source.read
                      else posterior_of(ctx, self.inputs.prior, source.round))
            proposal = self.proposer.build(origin, ProposalInputs(r, self.inputs.prior, self.probit, ctx.seed))
        return {"name": "prior" if proposal is None else self.proposer.name, "proposal": proposal,
                "source": source.round, "source_read": source.read}

    def proposal(self, ctx: RoundContext) -> ParameterDistribution:
        """The proposal stage's distribution; the prior where it has none."""
        proposal = ctx.output("proposal")["proposal"]
        return self.inputs.prior if proposal is None else proposal

    def _proposal_name(self, ctx: RoundContext) -> str:
        return ctx.output("proposal")["name"]

    def collect(self, ctx: RoundContext) -> dict:
        """The round's simulations under the collect policy. Where that policy replays the real trajectories with
        noise, the last rows (twice the held-out share) replay them as they were executed: the pairs the spread is
        calibrated on and the held-out pairs, drawn like the real data (docs/statistics.md, 'Simulations driven
        like the real system')."""
        rc = self.inputs.rc
        theta = self.proposal(ctx).sample((rc.collect.trajectories,), generator=torch.Generator().manual_seed(ctx.seed))
        policy = self.inputs.policy(ctx.seed, ctx)
        exact = policy.without_noise()
        n_exact = 0 if exact is None else 2 * held_out_count(len(theta), rc.diagnostics.held_out_fraction)
        cut = len(theta) - n_exact
        traj = self.inputs.sims.rollout(theta[:cut], policy, rc.collect.horizon, ctx.seed, rc.logging.progress)
        if n_exact:
            exact_seed = stage_seed(ctx.run_seed, ctx.round, "collect_exact")
            traj = Trajectories.cat([traj, self.inputs.sims.rollout(theta[cut:], exact, rc.collect.horizon, exact_seed)])
        return {"theta": theta.float(), "traj": traj.state_dict(), "exact": torch.arange(len(theta)) >= cut}

    def summarize(self, ctx: RoundContext) -> dict:
        return summarized(ctx.output("collect"), self.inputs.summarizer, self.inputs.device)

    def identifiability(self, ctx: RoundContext) -> dict:
        """What the round's summaries can say about each parameter (diagnostics/identifiability.py): the linear read
        of its training simulations, and in round 1 the local sensitivity at the nominal parameters, whose
        parameters that move nothing are said before any fit."""
        theta, x, _, _ = self._split(ctx.output("summarize"))
        d, names = self.inputs.rc.diagnostics, self.inputs.task.spec.names
        report = {**linear_read(x.to(self.inputs.device), self._fitted_space(theta), names), "local": None}
        if d.sensitivity_sims and ctx.round == 1:
            def simulate(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
                return summaries_at(points, task=self.inputs.task, sims=self.inputs.sims,
                                    policy=self.inputs.policy(ctx.seed, ctx), prior_std=self.inputs.prior.stddev,
                                    num=d.sensitivity_sims, horizon=self.inputs.rc.collect.horizon, seed=ctx.seed,
                                    summarize=self._summaries)

            report["local"] = sensitivity(simulate, nominal_point(self.inputs.task.spec, self.inputs.prior.stddev),
                                          column_scale(x.double()), names)
        log_findings(ctx.round, report)
        ctx.tb.identifiability(ctx.round, names, report)
        return report

    def fit(self, ctx: RoundContext) -> dict:
        r = ctx.round
        data = [self._training_split(ctx, k) for k in self._fitted_rounds(ctx)]
        theta, x = self._fitted_space(torch.cat([d[0] for d in data])), torch.cat([d[1] for d in data])
        model = self.inputs.model()
        if r > 1 and self.cfg.finetune:
            model.load_state_dict(ctx.output("fit", r - 1)["model"])
        self._truncate_to_box(model, r)
        # trained on the run's device (summaries are stored on the CPU; with device=cuda they are copied there)
        dev = self.inputs.device
        calibrated = calibration_rows(len(theta), len(data[-1][0]), self.cfg.calibrate_on)
        # simulations replayed as the real data were driven are kept for the calibration alone
        fraction = self.inputs.rc.diagnostics.held_out_fraction
        exact = torch.cat([exact_training_rows(ctx.output("summarize", k), fraction) for k in self._fitted_rounds(ctx)])
        history = model.fit(theta.to(dev), x.to(dev), seed=ctx.seed, label=f"round {r}", calibration_rows=calibrated,
                            calibration_only=exact if bool((exact & calibrated).any()) else None)
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

    def _truncate_to_box(self, model, r: int) -> None:
        """In parameter units (parameter_space=box) the conditioning truncates q to the prior's box; a model that can
        is trained and calibrated as that truncated mixture (models/box_mass.py). Probit space has no box."""
        low, high = getattr(self.inputs.prior, "low", None), getattr(self.inputs.prior, "high", None)
        if self.probit is not None or low is None or not hasattr(model, "set_support"):
            return
        low, high = torch.as_tensor(low, dtype=torch.float64), torch.as_tensor(high, dtype=torch.float64)
        if not (torch.isfinite(low).all() and torch.isfinite(high).all()):
            return
        if not model.set_support(low, high) and r == 1:
            log.info("parameter_space=box: the model's components have no box mass here (full covariance in more "
                     "than 2 parameters): trained untruncated")

    def _fitted_rounds(self, ctx: RoundContext) -> range:
        """The rounds whose simulations the round's model is trained on."""
        return range(1 if self.proposer.pools_rounds else ctx.round, ctx.round + 1)

    def _fitted_space(self, theta: torch.Tensor) -> torch.Tensor:
        return theta if self.probit is None else self.probit.to_probit(theta).float()

    def _fitted_prior(self) -> ParameterDistribution:
        return self.inputs.prior if self.probit is None else standard_normal_prior(self.probit.dim)

    def _split(self, summary: dict) -> tuple[torch.Tensor, ...]:
        return split(summary, self.inputs.rc.diagnostics.held_out_fraction)

    def _training_split(self, ctx: RoundContext, k: int) -> tuple[torch.Tensor, ...]:
        """Round k's simulations split as the model of round ctx.round is trained and checked on them: their
        summaries with this round's error model's noise (`_summary_error`), drawn in a stream of (round, k)."""
        summary = ctx.output("summarize", k)
        x = self._with_error(ctx, summary["x"], stage_seed(ctx.run_seed, ctx.round, f"summary_error_{k}"))
        return self._split({**summary, "x": x})

    def _summary_error(self, ctx: RoundContext) -> SummaryError | None:
        """The error model of round ctx.round's simulated summaries (summary_error.py): the features the previous
        round's replays left unexplained, with their variances, or where they read none the model that round ran
        with (SummaryError.carried); None in round 1, with method.summary_error=none or where nothing was left unexplained."""
        if self.cfg.summary_error == "none" or ctx.round == 1:
            return None
        return SummaryError.from_variance(ctx.output("condition", ctx.round - 1).get("feature_error"))

    def _with_error(self, ctx: RoundContext, x: torch.Tensor, seed: int) -> torch.Tensor:
        """Simulated summaries x with the round's error model's noise (the same x without one)."""
        error = self._summary_error(ctx)
        return x if error is None else error.add(x, torch.Generator().manual_seed(seed))

    def _fitted_model(self, ctx: RoundContext):
        model = self.inputs.model()
        model.load_state_dict(ctx.output("fit")["model"])
        self._truncate_to_box(model, 0)
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
                                         combination=self.cfg.combination, temperature=product_tau * temperature,
                                         importance_draws=self.cfg.importance_draws)
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
               "tempering": None, "product_temperature": product_record, "feature_error": None}
        if not replayable:
            out["posterior"] = condition_at(1.0)
        else:
            error = self._summary_error(ctx)

            def check(posterior):
                return replayed_check(lambda theta, which: replay(self.inputs.sims, theta, real, which), real, posterior,
                                      self.inputs.prior, summarize=self._summaries, num=d.replay_sims, seed=ctx.seed,
                                      alpha=d.mismatch_alpha, max_distance_ratio=d.mismatch_distance_ratio,
                                      modelled=None if error is None else error.modelled)

            out["posterior"], first, result, out["temperature"], out["tempering"] = temper_to_replays(
                condition_at, check, torch.diag(self.inputs.prior.stddev.double() ** 2), widen=self.cfg.replay_tempering)
            out["replay_check"], out["unwidened_replay_check"] = result.record(), first.record()
            # the next round's error model (_summary_error)
            out["feature_error"] = first.feature_error if error is None else error.carried(first.feature_error)
            ctx.tb.replays(ctx.round, result, list(self.inputs.task.obs_names))
        out["dispersion"] = None if spreads[-1] is None else spreads[-1].record()
        out["temperature"] *= product_tau
        return out

    def _product_temperature(self, ctx: RoundContext, model, n: int) -> tuple[float, dict | None]:
        """For products of n > 1 trajectories (the real ones; for the local check, those and one simulated): the
        temperature fitted on sets of n simulations at the round's held-out parameters (set_calibration.py);
        (1, None) for one trajectory or without sets."""
        d = self.inputs.rc.diagnostics
        theta = self._split(ctx.output("summarize"))[2][:d.combination_sets].double()
        if n < 2 or len(theta) == 0:
            return 1.0, None
        seed = stage_seed(ctx.run_seed, ctx.round, "product_temperature")  # its own stream, as the checks'
        tau, record = simulated_sets_temperature(
            theta, n, lambda theta_sets: self._simulate(ctx, theta_sets, seed),
            lambda x: self._simulated_set_products(ctx, [[model.conditional(x_i.float()) for x_i in x_set]
                                                         for x_set in x]),
            d.levels, d.coverage_samples, seed)
        if tau < 1:
            log.info("round %d: products of %d trajectories widened to temperature %.3g (fitted on %d simulated sets)",
                     ctx.round, n, tau, record["sets"])
        return tau, record

    def _simulated_set_product(self, ctx: RoundContext, conditionals: list) -> Callable[[float], ParameterDistribution]:
        """The posterior given a simulated set's per-trajectory posteriors, combined as the real set's are: their
        product tempered to the temperature it is called with (computed once); where it has no closed form, an
        importance pool of set_calibration.set_importance_draws, without a warning per set."""
        draws = set_importance_draws(self.cfg.importance_draws, self.inputs.rc.diagnostics.coverage_samples)
        return tempered_product(conditionals, self.inputs.prior, self.cfg.max_components, self.proposal(ctx), ctx.seed,
                                self.probit, draws, warn=False)

    def _simulated_set_products(self, ctx: RoundContext, sets: list[list]) -> Callable[[float], SetPosteriors]:
        """`_simulated_set_product` of many sets at once (condition.tempered_products): where every set's posterior
        is in closed form, their MixtureStack on the run's device, read together by set_calibration.py."""
        draws = set_importance_draws(self.cfg.importance_draws, self.inputs.rc.diagnostics.coverage_samples)
        return tempered_products(sets, self.inputs.prior, self.cfg.max_components, self.proposal(ctx), ctx.seed,
                                 self.probit, draws, self.inputs.device)

    def _simulate(self, ctx: RoundContext, theta: torch.Tensor, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        """simulate_as_driven at theta, its summaries with the round's error model's noise (the real data are a
        simulation plus that error)."""
        kept, x = simulate_as_driven(self.inputs.sims, self.inputs.policy(seed, ctx), theta,
                                     self.inputs.rc.collect.horizon, seed, self._summaries)
        return kept, self._with_error(ctx, x, seed)

    def _summaries(self, traj: Trajectories) -> torch.Tensor:
        return self.inputs.summarizer(traj.to(self.inputs.device)).cpu()

    def model_check(self, ctx: RoundContext) -> dict:
        """Can the simulator, at parameters the posterior allows, reproduce the real data? The summary
        predictive check and the mismatch verdict (diagnostics/mismatch.py) from the real summaries'
        place among the simulated ones, the replayed check (condition) and the dispersion. And does the model
        know the real data: do they lie among its training simulations, is it calibrated there (the guard reads
        `extrapolation` and `local_coverage`)?"""
        d, conditioned = self.inputs.rc.diagnostics, ctx.output("condition")
        # the simulator's own summaries, without the error model's noise: a mismatch is what it cannot reproduce
        _, x_train, _, x_held = self._split(ctx.output("summarize"))
        outside = summaries_outside(conditioned["x_real"], x_train, x_held)
        return {"predictive_distance": self._predictive(ctx, conditioned["posterior"], conditioned["x_real"]),
                "mismatch": mismatch_report(ctx.round, outside, conditioned["unwidened_replay_check"],
                                            conditioned["dispersion"], d.mismatch_alpha),
                "extrapolation": self._extrapolation(ctx, conditioned["x_real"]),
                "local_coverage": self._local_coverage(ctx, conditioned)}

    def _extrapolation(self, ctx: RoundContext, x_real: torch.Tensor) -> dict | None:
        """model_checks.extrapolation on the rounds the model is trained on (None without held-out simulations or
        with `diagnostics.extrapolation_alpha` 0)."""
        alpha = self.inputs.rc.diagnostics.extrapolation_alpha
        data = [self._training_split(ctx, k) for k in self._fitted_rounds(ctx)]
        if alpha == 0 or len(data[-1][3]) == 0:
            return None
        return extrapolation(self._fitted_model(ctx), data, self._fitted_space, x_real, alpha, ctx.seed)

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
        return {**coverage_near_real(model, x_real, lambda theta: self._simulate(ctx, theta, seed),
                                     lambda conditionals: self._simulated_set_product(ctx, conditionals)(tau),
                                     d.local_sets, d.levels, d.coverage_samples, seed), "temperature": tau}

    def _predictive(self, ctx: RoundContext, posterior, x_real: torch.Tensor) -> dict | None:
        num, horizon = self.inputs.rc.diagnostics.predictive_sims, self.inputs.rc.collect.horizon
        if num == 0:
            return None
        return predictive_distances(
            lambda theta: predictive_summaries(self.inputs.sims, self.inputs.policy(ctx.seed, ctx), theta, horizon,
                                               ctx.seed, self.inputs.summarizer, self.inputs.device),
            x_real, posterior, self.inputs.prior, num, ctx.seed)

    def guard(self, ctx: RoundContext) -> dict:
        """The guard's findings (diagnostics/guard.py), what the round hands on to domain randomization and what
        the next round proposes from. A round that passes: its own posterior, for both. With on_guard=fallback and a
        failure, domain randomization gets what the previous round handed on (the prior before round 1); the next
        round proposes from this round's posterior where every failure says only that the real data lie outside
        the simulations (method.escape: simulating where it points is what cures that), else from what this round
        proposed from (more simulations from the same proposal). A round that simulated from a read of its real
        data and passes is `provisional` under on_guard=fallback: its checks saw only the read's region, which need
        not hold the truth (a read beyond it passed Cartpole's corner at -9.3 nats), so the next round proposes from
        its posterior and domain randomization keeps what it had until a round proposing from there passes."""
        r, held_out, checked = ctx.round, ctx.output("fit")["held_out"] or {}, ctx.output("model_check")
        conditioned = ctx.output("condition")
        baseline = "prior" if self._proposal_name(ctx) == "prior" else f"round's proposal ({self._proposal_name(ctx)})"
        # real trajectories replayed, and the posterior widened by what the replays leave unexplained: that comparison
        # with simulations near the posterior stands in for the distance from the training ones (docs/statistics.md),
        # where the widening reached the real data; one that stopped at its floor still too narrow cannot, and one
        # that found nothing to widen for measured no model error: the distance then says what it says without
        # replays (Cartpole at 3 % of every range: replays as near as its own simulations', -18.4 nats handed on)
        replayed, tempering = conditioned["replay_check"], conditioned["tempering"]
        # (tempering is None where nothing was replayed or method.replay_tempering is off)
        widened_by_replays = tempering is not None and tempering[-1]["temperature"] < 1 and not replayed["too_narrow"]
        report = check_posterior(held_out.get("gain_over_proposal"), (ctx.output("fit")["coverage"] or {}).get("hpd"),
                                 held_out.get("count", 0), baseline, conditioned["posterior"].effective_sample_size,
                                 local=checked.get("local_coverage"),
                                 extrapolation=None if widened_by_replays else checked.get("extrapolation"),
                                 outside_range=None if widened_by_replays else flag_outside(
                                     checked["mismatch"]["summaries_outside"],
                                     self.inputs.rc.diagnostics.extrapolation_alpha))
        simulated_from = self._simulated_from(ctx)
        action = self.cfg.on_guard if report.failed else "warn" if report.warnings else "none"
        if action in ("none", "warn") and self.cfg.on_guard == "fallback" and simulated_from.read:
            action = "provisional"
        source, proposes, read = r, ProposalSource(r), None
        if action in ("provisional", "fallback"):
            source = handed_on_round(ctx, r - 1)
        if action == "fallback":
            if self.cfg.escape == "none" or not report.near_real_data_only:  # the model failed: simulate more alike
                proposes = simulated_from
            elif (escape := self._escape(ctx)) in READS:
                read = self._read(ctx, escape)
                proposes = ProposalSource(r, escape)
        for warning in report.warnings:
            log.warning("round %d: %s", r, warning)
        if action == "provisional":
            log.warning("round %d: the guard passed a round that simulated from %s, whose region its checks cannot see "
                        "past: the next round proposes from its posterior, domain randomization keeps %s until a "
                        "round proposing from there passes", r, simulated_from.describe(), handed_on_name(source))
        if action == "fallback":
            why = (f"its real data lie outside its simulations: method.escape={self.cfg.escape}"
                   if proposes.round == r else "as this round did")
            log.warning("round %d: the guard failed; domain randomization gets %s instead (method.on_guard=fallback); "
                        "the next round proposes from %s (%s)", r, handed_on_name(source), proposes.describe(), why)
        return {**report.to_dict(), "action": action, "handed_on": source, "proposes_from": proposes.round,
                "proposes_read": proposes.read, "read": read}

    @staticmethod
    def _simulated_from(ctx: RoundContext) -> ProposalSource:
        """What this round's proposal was built from (its proposal stage records it)."""
        proposal = ctx.output("proposal")
        return ProposalSource(proposal["source"], proposal["source_read"])

    def _escape(self, ctx: RoundContext) -> str:
        """method.escape for this round: linear_then_posterior is `linear` unless the round simulated from a read."""
        if self.cfg.escape != "linear_then_posterior":
            return self.cfg.escape
        return "posterior" if self._simulated_from(ctx).read else "linear"

    def _read(self, ctx: RoundContext, escape: str) -> dict:
        """escape.read_at (the `escape` read) on the rounds the model is trained on: their training rows fitted,
        the round's held-out rows checked, read at the real summaries, in the model's coordinates."""
        data = [self._training_split(ctx, k) for k in self._fitted_rounds(ctx)]
        mean, cov = read_at(torch.cat([d[1] for d in data]), self._fitted_space(torch.cat([d[0] for d in data])),
                            data[-1][3], self._fitted_space(data[-1][2]),
                            ctx.output("condition")["x_real"].reshape(-1, data[-1][3].shape[-1]),
                            nearest=escape == "nearest")
        return {"mean": mean, "cov": cov}

    def _read_distribution(self, read: dict) -> ParameterDistribution:
        """The Gaussian of a read, in parameter units: mapped back from probit space, or truncated to the box."""
        gaussian = GaussianMixture(torch.zeros(1), read["mean"][None], read["cov"][None])
        if self.probit is not None:
            return ProbitPosterior(gaussian, self.probit)
        return TruncatedMixture(gaussian, self.inputs.prior.low, self.inputs.prior.high)

    # results -------------------------------------------------------------------------
    def posterior(self, ctx: RoundContext) -> ParameterDistribution:
        return handed_on(ctx, self.inputs.prior)

    def handed_on_round(self, ctx: RoundContext) -> int:
        return handed_on_round(ctx, ctx.round)

    def stop_reason(self, ctx: RoundContext) -> str | None:
        guard = ctx.output("guard")
        if guard["action"] != "stop":
            return None
        return f"round {ctx.round}: the guard failed (method.on_guard=stop): " + "; ".join(guard["warnings"])

    def added_round(self, ctx: RoundContext) -> str | None:
        """An escape under way at the last planned round: it handed on nothing of its own (a fallback, or a
        provisional round) and the next round would propose from where it points (its posterior or a read of its
        real data), not from where it simulated. The round after it is added, at most method.escape_rounds past
        `rounds`: the escape's cycle (a read, then the read's round's posterior) takes two rounds, and a run that
        ends inside it hands on what the last passing round did, the prior on a robot outside the prior's
        simulations (docs/benchmarks.md, "Rounds added for an escape under way")."""
        guard, asked, most = ctx.output("guard"), self.inputs.rc.rounds, self.cfg.escape_rounds
        if (ctx.round >= asked + most or guard["action"] not in ("provisional", "fallback")
                or guard["proposes_from"] != ctx.round):
            return None
        moved = ProposalSource(guard["proposes_from"], guard["proposes_read"]).describe()
        return (f"round {ctx.round} handed on {handed_on_name(guard['handed_on'])} (its guard: {guard['action']}) "
                f"and the next round proposes from {moved}: the escape goes on for round {ctx.round + 1} (at most "
                f"{asked + most}: rounds={asked} plus method.escape_rounds={most})")

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
            "proposal": self._proposal_name(ctx),
            "proposal_from": self._simulated_from(ctx).describe(),
            "coverage": fitted["coverage"],
            "held_out": fitted["held_out"],
            "identifiability": {k: v for k, v in ctx.output("identifiability").items() if k != "seconds"},
            "guard": {**{k: guard[k] for k in ("ok", "failed", "near_real_data_only", "warnings", "action")},
                      "handed_on": handed_on_name(guard["handed_on"]),
                      "proposes_from": ProposalSource(guard["proposes_from"], guard["proposes_read"]).describe()},
            "dispersion": conditioned["dispersion"],
            "temperature": conditioned["temperature"],
            "product_temperature": conditioned["product_temperature"],
            "replay_check": conditioned["replay_check"],
            "summary_error": None if (error := self._summary_error(ctx)) is None else error.record(),
            **{k: v for k, v in ctx.output("model_check").items() if k != "seconds"},
        }



def bayessim(cfg: BayesSimConfig, inputs: MethodInputs) -> BayesSim:
    return BayesSim(cfg, inputs)

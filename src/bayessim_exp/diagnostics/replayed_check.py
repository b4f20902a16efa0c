"""Posterior predictive check by replay: does each real trajectory lie where the posterior's replays do?

For real trajectory i, `num` parameter draws from the posterior and `num` from the prior are each
replayed from trajectory i's initial state under its actions (diagnostics/replay.py). Real trajectory
and replays are compared through what the inference sees of them, their summaries, each feature divided
by its spread over the prior's replays (features that do not vary there, the replayed actions, are left
out); distances are root-mean-squares over the features. Summaries rather than whole trajectories: a
pendulum's replays at nearby parameters drift apart within seconds, so the late steps of a long
trajectory measure that drift, not the parameters.

Around the posterior the replayed summaries are close to linear in the parameters: a least-squares fit
s(theta) = a + B (theta - mean) over the posterior's replays gives each summary its implied parameters,
the theta whose fitted summary is nearest, and the residual, its distance from the fit. Per trajectory
the check reports:
- `p_value`: the rank of the real summary's implied parameters among the replays' own, by their
  Mahalanobis distance from the replays' mean under the replays' covariance:
  p = (1 + #{j : M_j >= M_real}) / (m + 1), m the replays that did not diverge. If the truth were a
  posterior draw and the simulator the real system, the real summary would be a replay like the others
  and p uniform (in steps of 1 / (m + 1)). Parameters, not summary distances: a summary that varies
  strongly with one parameter would hide a miss in another behind the first one's spread;
- `residual`: the real summary's distance from the fit, what no parameter near the posterior explains;
  `residual_baseline`, the replays' own median distance from it (the fit's curvature); and
  `residual_p_value`, the real residual's rank among the replays' ones, as p_value is computed;
- the median distances of the real summary to the posterior's and to the prior's replays.
Where the residual is beyond the replays' (residual_p_value <= alpha), its excess is a model error, read per
feature: v_f, the real residual's square in feature f beyond the replays' median square there. The check gives
the parameter covariance that least squares would have with errors of those variances in the features,
G^-1 B^T diag(v) B G^-1 with G = B^T B (the sandwich estimator), averaged over the real trajectories
(`model_error_covariance`): an error in features the parameters barely move costs little width, one in features
that pin a parameter down costs that parameter's. (Until 6bdc798 it was r^2 G^-1, r^2 the whole residual's
excess: as if every feature carried all of the error, for an error spread over F features about F times the
variance; docs/statistics.md has what each kept on the foreign-dynamics benchmark.)

The same excess read as a summary error model (inference/bayessim/summary_error.py): `feature_error`, per
feature in the summaries' own units, the real residual's square where it lies beyond every replay's and beyond
a Bonferroni bound (alpha over the features) on the replays' scale there (their median square over chi^2_1's
median), averaged over the real trajectories; 0 elsewhere. With features in an error model (`modelled`) the
implied parameters, their p-values and `model_error_covariance` are read from the other features, as the model
trained with that noise reads the parameters from them (replays with the noise added instead held any real data
whose noisy features dominate the unweighted fit, and physics the model lacks went unwidened: docs/statistics.md);
the residuals, the flag and `feature_error` stay on all features: what the simulator itself leaves unexplained.
Where the other features' residual is still beyond the replays' (an error spread over the features, not in a
few), `model_error_covariance` is read on all features and the p-value is the smaller of the two reads'.

Two readings (docs/statistics.md):
- `too_narrow`: p <= alpha, the real data's implied parameters lie outside the posterior. Either the
  posterior misses the truth or no parameter value reproduces the data exactly (a simulator slightly
  unlike the real system) and the posterior is narrower than that model error; widening it
  (inference/bayessim/replay_tempering.py) is the remedy for both. A posterior whose draws all share a
  parameter's value is too narrow wherever the residual is beyond the replays': the replays cannot tell
  where along that parameter the real data lie.
- `flagged` (model mismatch): the residual is beyond the replays' and its excess exceeds
  `max_distance_ratio` of the real summary's median distance to the prior's replays: at the parameters
  the posterior concentrates on, the simulator leaves a sizeable part of what the prior could not explain
  unexplained. Read on the posterior before any widening, which concentrates where the simulator fits
  best. Both conditions: replays of a swinging pendulum near an unstable balance scatter widely around
  any fit, and a real residual as large as theirs is no sign of mismatch; a significant but small excess
  (another integrator's) is no reason to doubt the model either.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import torch

from ..models.base import constant_columns
from ..sim.trajectories import Trajectories


@dataclasses.dataclass
class ReplayCheck:
    distance_posterior: list[float]
    distance_prior: list[float]
    residual: list[float]
    residual_baseline: list[float]
    residual_p_value: list[float]
    p_value: list[float]
    alpha: float
    max_distance_ratio: float
    real: Trajectories
    posterior_states: torch.Tensor  # [n, num, T+1, S] replays at posterior draws
    prior_states: torch.Tensor
    posterior_covariance: torch.Tensor  # [D, D] of the replayed draws
    model_error_covariance: torch.Tensor  # [D, D] (module docstring)
    feature_error: torch.Tensor  # [F] variances in the summaries' units (module docstring)

    @property
    def too_narrow(self) -> list[int]:
        """The real trajectories whose implied parameters lie outside the posterior."""
        return [i for i, p in enumerate(self.p_value) if p <= self.alpha]

    @property
    def excess_ratios(self) -> list[float]:
        """Per real trajectory: the residual's excess over the baseline, over the distance to the prior's replays."""
        return [_excess(res, base) / prior for res, base, prior in
                zip(self.residual, self.residual_baseline, self.distance_prior)]

    @property
    def flagged(self) -> list[int]:
        """The real trajectories the simulator does not explain at the parameters the posterior allows."""
        return [i for i, (p, ratio) in enumerate(zip(self.residual_p_value, self.excess_ratios))
                if p <= self.alpha and ratio > self.max_distance_ratio]

    def record(self) -> dict:
        """What results.json keeps (per real trajectory, in the file's order, and the extremes over them)."""
        return {"distance_posterior": self.distance_posterior, "distance_prior": self.distance_prior,
                "residual": self.residual, "residual_baseline": self.residual_baseline,
                "residual_p_value": self.residual_p_value, "excess_ratio": self.excess_ratios, "p_value": self.p_value,
                "alpha": self.alpha, "max_distance_ratio": self.max_distance_ratio, "too_narrow": self.too_narrow,
                "flagged": self.flagged, "min_p_value": min(self.p_value), "max_excess_ratio": max(self.excess_ratios)}


def _excess(residual: float, baseline: float) -> float:
    return math.sqrt(max(0.0, residual**2 - baseline**2)) if math.isfinite(residual) else math.inf


def replayed_check(simulate: Callable[[torch.Tensor, torch.Tensor], Trajectories], real: Trajectories,
                   posterior, prior, *, summarize: Callable[[Trajectories], torch.Tensor], num: int, seed: int,
                   alpha: float, max_distance_ratio: float, modelled: torch.Tensor | None = None) -> ReplayCheck:
    """simulate(params [N, D], which [N]) replays real trajectory which[k] at params[k] (replay.replay);
    summarize(trajectories) -> [N, F], the run's summarizer; modelled [F] bool: the features the run's summary
    error model puts noise in (inference/bayessim/summary_error.py), or None."""
    n = real.num
    which = torch.arange(n).repeat_interleave(num)
    g = torch.Generator().manual_seed(seed)  # its own stream: the check never moves the inference's draws
    theta_post = posterior.sample((n * num,), generator=g).double()
    theta_prior = prior.sample((n * num,), generator=g).double()
    post, pri = simulate(theta_post, which), simulate(theta_prior, which)
    x_post = summarize(post).double().reshape(n, num, -1)
    x_prior = summarize(pri).double().reshape(n, num, -1)
    ok_post = (~post.diverged.cpu()).reshape(n, num) & torch.isfinite(x_post).all(-1)
    ok_prior = (~pri.diverged.cpu()).reshape(n, num) & torch.isfinite(x_prior).all(-1)
    x_real = summarize(real).double()
    dim, features = theta_post.shape[1], x_real.shape[1]
    modelled = torch.zeros(features, dtype=torch.bool) if modelled is None else modelled.cpu()
    posterior_covariance = torch.atleast_2d(torch.cov(theta_post.T))
    theta_post = theta_post.reshape(n, num, -1)
    d_post, d_prior, residuals, baselines, residual_p, p_values = [], [], [], [], [], []
    error_covariance = torch.zeros(dim, dim, dtype=torch.float64)
    feature_error = torch.zeros(features, dtype=torch.float64)
    for i in range(n):
        sims, reference, theta = x_post[i][ok_post[i]], x_prior[i][ok_prior[i]], theta_post[i][ok_post[i]]
        if len(sims) <= dim + 1 or len(reference) < 2:  # the draws diverged on this trajectory's actions
            for values in (d_post, d_prior, residuals, baselines):
                values.append(math.inf)
            residual_p.append(0.0), p_values.append(0.0)
            continue
        scale = reference.std(0)
        keep = ~constant_columns(reference)
        z_sims, z_real = standardised(sims, scale, keep), standardised(x_real[i : i + 1], scale, keep)
        d_post.append(float(torch.cdist(z_sims, z_real)[:, 0].median()))
        d_prior.append(float(torch.cdist(standardised(reference, scale, keep), z_real)[:, 0].median()))
        implied, residual, gram, slopes, per_feature = implied_parameters(z_sims, theta, torch.cat([z_sims, z_real]))
        residuals.append(float(residual[-1]))
        baselines.append(float(residual[:-1].median()))
        residual_p.append(rank_p_value(residual[:-1], residual[-1]))
        if residual_p[-1] <= alpha:
            # standardised() divided feature f by scale_f sqrt(kept): its variance, back in the summaries' units
            to_units = (scale[keep] * math.sqrt(int(keep.sum()))) ** 2
            feature_error[keep] += unexplained_features(per_feature, alpha) * to_units / n
        p_value, explained = implied_p_value(implied), False
        read = ~modelled[keep]  # the features the model reads the parameters from
        if not bool(read.all()) and int(read.sum()) > dim:
            reduced, reduced_residual, _, _, _ = implied_parameters(z_sims[:, read], theta,
                                                                    torch.cat([z_sims, z_real])[:, read])
            explained = rank_p_value(reduced_residual[:-1], reduced_residual[-1]) > alpha
            # explained: the parameters read from the other features, as q reads them, and no model error left to
            # widen for; else those features carry model error too (physics the model lacks) and the parameters
            # read from them need not hold it: the error read on all features, the nearer of the two p-values
            p_value = implied_p_value(reduced) if explained else min(p_value, implied_p_value(reduced))
        if residual_p[-1] <= alpha and not explained:
            # per feature, the real residual's square beyond the replays' median square: the parameter covariance
            # of least squares with that error in each feature (the sandwich G^-1 B^T diag(v) B G^-1)
            excess = (per_feature[-1] ** 2 - per_feature[:-1].pow(2).median(0).values).clamp_min(0.0)
            inverse = torch.linalg.inv(gram)
            error_covariance += inverse @ (slopes.T * excess) @ slopes @ inverse / n
        if residual_p[-1] <= alpha and bool((theta.std(0) == 0).any()):
            # a parameter every draw shares (a probit posterior saturated on the box's face) has no slope, so its
            # implied value is the draws' own: the real data not reproduced, that width of zero is too narrow
            p_value = 1.0 / len(implied)
        p_values.append(p_value)
    states_post = post.states.double().cpu().reshape(n, num, *post.states.shape[1:])
    states_prior = pri.states.double().cpu().reshape(n, num, *pri.states.shape[1:])
    return ReplayCheck(d_post, d_prior, residuals, baselines, residual_p, p_values, alpha, max_distance_ratio, real,
                       states_post, states_prior, posterior_covariance, error_covariance, feature_error)


_CHI2_1_MEDIAN = 0.45493642311957283  # of chi^2 with one degree of freedom


def unexplained_features(per_feature: torch.Tensor, alpha: float) -> torch.Tensor:
    """per_feature [m + 1, F]: the replays' residuals feature by feature, the real summary's last. The real
    residual's square in each feature where it lies beyond every replay's and beyond chi^2_1's 1 - alpha / F
    quantile on the replays' scale (their median square over chi^2_1's median); 0 elsewhere."""
    replays, real = per_feature[:-1].pow(2), per_feature[-1].pow(2)
    features = per_feature.shape[1]
    bound = float(torch.special.ndtri(torch.tensor(1 - alpha / (2 * features), dtype=torch.float64))) ** 2
    scale = replays.median(0).values / _CHI2_1_MEDIAN
    beyond = (real > replays.max(0).values) & (real > bound * scale)
    return torch.where(beyond, real, torch.zeros_like(real))


def implied_p_value(implied: torch.Tensor) -> float:
    """implied [m + 1, D], the real summary's last: the rank of its Mahalanobis distance from the replays' mean
    under their covariance among the replays' own."""
    spread = torch.linalg.pinv(torch.atleast_2d(torch.cov(implied[:-1].T)))
    centred = implied - implied[:-1].mean(0)
    mahalanobis = ((centred @ spread) * centred).sum(1)
    return rank_p_value(mahalanobis[:-1], mahalanobis[-1])


def rank_p_value(replays: torch.Tensor, real: torch.Tensor) -> float:
    """(1 + #{replays at least as large as the real value}) / (count + 1): a p-value, uniform in steps of
    1 / (count + 1) when the real value is exchangeable with the replays'."""
    return float(1 + (replays >= real).sum()) / (len(replays) + 1)


def implied_parameters(z: torch.Tensor, theta: torch.Tensor,
                       queries: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """The least-squares linear map z ~ a + B (theta - mean) over the replays (z [m, F], theta [m, D]);
    for each query summary [k, F] its implied parameters [k, D], its RMS residual from the map [k]; B^T B; the
    slopes B [F, D]; and each query's residual per feature [k, F]. Both normal matrices are regularised by a relative 1e-9: a parameter the replays do not vary
    (every posterior draw on the box's edge) or the summaries ignore gets no slope and its mean as implied value."""
    mean_theta, mean_z = theta.mean(0), z.mean(0)
    design = theta - mean_theta
    # the normal equations (D unknowns per feature, D <= tens): LAPACK's least squares gave results that
    # differed in the last digit from run to run
    B = torch.linalg.solve(_ridged(design.T @ design), design.T @ (z - mean_z)).T  # [F, D]
    gram = _ridged(B.T @ B)
    offsets = torch.linalg.solve(gram, B.T @ (queries - mean_z).T).T  # [k, D]
    per_feature = queries - mean_z - offsets @ B.T
    return mean_theta + offsets, per_feature.norm(dim=1), gram, B, per_feature


def _ridged(normal: torch.Tensor) -> torch.Tensor:
    return normal + 1e-9 * normal.diagonal().mean().clamp_min(1e-300) * torch.eye(len(normal), dtype=normal.dtype)


def standardised(x: torch.Tensor, scale: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
    """Summaries [m, F] -> the varying features over their spread, divided by sqrt(count) so that
    Euclidean distances between rows are RMS differences."""
    return x[:, keep] / scale[keep] / math.sqrt(max(int(keep.sum()), 1))

"""A round's distribution against the prior: moments, the log density of the true parameters, and where
the truth lies in the distribution.

log p_post(theta*) - log p_prior(theta*) (the log-density gain) is how much the distribution knows
about the true parameters beyond the prior. `truth` places theta* among the distribution's draws: its
HPD level (the share of draws with a higher density; theta* lies in the level-L highest-density
region iff it is below L) and per parameter its marginal rank (the share of draws below it: an SBC
rank over the number of draws, uniform over truths drawn from the prior when the pipeline is
calibrated). The calibration study (sweeps/calibration.yaml) reads both. Values that are not finite
(a truth outside the support) are written as None, so results.json stays strict JSON.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..distributions.base import QUANTILE_LEVELS, ParameterDistribution
from ..distributions.hpd import hpd_level


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


TRUTH_DRAWS = 4000  # posterior draws the truth is ranked among (a share's standard error <= 0.008)


def truth_rank(posterior: ParameterDistribution, names: list[str], true: np.ndarray, seed: int) -> dict:
    """{"hpd_level": hpd_level of theta* among TRUTH_DRAWS draws, "marginal_rank": {name: share of draws
    below theta*_d}, "hpd_level_probit": the same draws' and theta*'s HPD level in probit space (None for a
    posterior not defined there)}. The probit map's Jacobian makes the two spaces' regions different sets of the
    same mass: the model's spread is calibrated, and the guard reads its regions, in probit space
    (docs/statistics.md, "Which space the regions live in")."""
    t = torch.as_tensor(true, dtype=torch.float64)[None]
    g = torch.Generator().manual_seed(seed)
    draws = posterior.sample((TRUTH_DRAWS,), generator=g).double()
    out = {"hpd_level": hpd_level(posterior, t, draws, g),
           "marginal_rank": dict(zip(names, (draws < t).double().mean(0).tolist())), "hpd_level_probit": None}
    in_probit = posterior.in_probit_space()
    if in_probit is not None:
        to_probit = posterior.transform.to_probit
        out["hpd_level_probit"] = hpd_level(in_probit, to_probit(t), to_probit(draws), g)
    return out


def quantile_key(level: float) -> str:
    """The name of a quantile level in results.json and the exports: 0.05 -> "q05", 0.995 -> "q99.5"."""
    percent = round(100 * level, 6)
    return f"q{int(percent):02d}" if percent == int(percent) else f"q{percent:g}"


def quantile_table(dist: ParameterDistribution, names: list[str],
                   levels: tuple[float, ...] = QUANTILE_LEVELS) -> dict[str, dict[str, float]]:
    """{"q05": {name: value}, "q50": ..., "q95": ...}: per-parameter quantiles (ParameterDistribution.quantiles)."""
    q = dist.quantiles(levels)
    return {quantile_key(level): dict(zip(names, row.tolist())) for level, row in zip(levels, q)}


def score(posterior: ParameterDistribution, prior: ParameterDistribution, names: list[str],
          true: np.ndarray | None, seed: int = 0) -> dict:
    """Moments, 5/50/95 % quantiles, `contraction` (per parameter 1 - posterior variance / prior variance: 0 where
    the data taught nothing, 1 where they pin it down; beside the identifiability report's R^2), and where the
    truth lies."""
    post_std, prior_std = posterior.stddev.double(), prior.stddev.double()
    out = {
        "posterior_mean": dict(zip(names, posterior.mean.double().tolist())),
        "posterior_std": dict(zip(names, post_std.tolist())),
        "posterior_quantiles": quantile_table(posterior, names),
        "prior_std": dict(zip(names, prior_std.tolist())),
        "contraction": dict(zip(names, (1 - (post_std / prior_std) ** 2).tolist())),
        "log_prob_true_posterior": None, "log_prob_true_prior": None, "log_prob_gain": None, "truth": None,
    }
    if true is not None:
        t = torch.as_tensor(true, dtype=torch.float64)[None]
        lp_post, lp_prior = float(posterior.log_prob(t)), float(prior.log_prob(t))
        out.update(log_prob_true_posterior=_finite_or_none(lp_post), log_prob_true_prior=_finite_or_none(lp_prior),
                   log_prob_gain=_finite_or_none(lp_post - lp_prior), truth=truth_rank(posterior, names, true, seed))
    return out

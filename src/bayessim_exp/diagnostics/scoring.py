"""A round's distribution against the prior: moments, and the log density of the true parameters.

log p_post(theta*) - log p_prior(theta*) (the log-density gain) is how much the distribution knows
about the true parameters beyond the prior. Values that are not finite (a truth outside the
support) are written as None, so results.json stays strict JSON.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..distributions.base import ParameterDistribution


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def score(posterior: ParameterDistribution, prior: ParameterDistribution, names: list[str],
          true: np.ndarray | None) -> dict:
    out = {
        "posterior_mean": dict(zip(names, posterior.mean.double().tolist())),
        "posterior_std": dict(zip(names, posterior.stddev.double().tolist())),
        "prior_std": dict(zip(names, prior.stddev.double().tolist())),
        "log_prob_true_posterior": None, "log_prob_true_prior": None, "log_prob_gain": None,
    }
    if true is not None:
        t = torch.as_tensor(true, dtype=torch.float64)[None]
        lp_post, lp_prior = float(posterior.log_prob(t)), float(prior.log_prob(t))
        out.update(log_prob_true_posterior=_finite_or_none(lp_post), log_prob_true_prior=_finite_or_none(lp_prior),
                   log_prob_gain=_finite_or_none(lp_post - lp_prior))
    return out

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

from ..distributions.base import ParameterDistribution


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


TRUTH_DRAWS = 4000  # posterior draws the truth is ranked among (a share's standard error <= 0.008)


def hpd_level(posterior: ParameterDistribution, theta: torch.Tensor, draws: torch.Tensor,
              generator: torch.Generator) -> float | None:
    """The share of `draws` (from posterior) denser than theta [1, D]: theta lies in the level-L HPD region iff
    it is below L; None where theta has no density. Draws as dense as theta (a flat distribution: the prior
    handed on by the guard) count by a uniform share of them, so a flat distribution's level is uniform."""
    at_theta = float(posterior.log_prob(theta))
    if not math.isfinite(at_theta):
        return None
    lp = posterior.log_prob(draws)
    ties = float((lp == at_theta).double().mean())
    return float((lp > at_theta).double().mean()) + float(torch.rand(1, generator=generator, dtype=torch.float64)) * ties



def own_level(posterior: ParameterDistribution, theta: torch.Tensor, draws: int, generator: torch.Generator) -> float:
    """hpd_level of a simulation's own parameters theta [D] among `draws` fresh draws of the posterior given it;
    1 (outside every region) where the posterior has no density there."""
    level = hpd_level(posterior, theta[None], posterior.sample((draws,), generator=generator).double(), generator)
    return 1.0 if level is None else level


def shares_inside(levels_of: torch.Tensor, levels) -> dict[str, float]:
    """{level: share of the HPD levels `levels_of` below it}: how often the level-L regions held their parameters."""
    return {f"{level:g}": float((levels_of < level).double().mean()) for level in levels}


def truth_rank(posterior: ParameterDistribution, names: list[str], true: np.ndarray, seed: int) -> dict:
    """{"hpd_level": hpd_level of theta* among TRUTH_DRAWS draws, "marginal_rank": {name: share of draws
    below theta*_d}}."""
    t = torch.as_tensor(true, dtype=torch.float64)[None]
    g = torch.Generator().manual_seed(seed)
    draws = posterior.sample((TRUTH_DRAWS,), generator=g).double()
    return {"hpd_level": hpd_level(posterior, t, draws, g),
            "marginal_rank": dict(zip(names, (draws < t).double().mean(0).tolist()))}


def score(posterior: ParameterDistribution, prior: ParameterDistribution, names: list[str],
          true: np.ndarray | None, seed: int = 0) -> dict:
    """Moments, `contraction` (per parameter 1 - posterior variance / prior variance: 0 where the data taught
    nothing, 1 where they pin it down; beside the identifiability report's R^2), and where the truth lies."""
    post_std, prior_std = posterior.stddev.double(), prior.stddev.double()
    out = {
        "posterior_mean": dict(zip(names, posterior.mean.double().tolist())),
        "posterior_std": dict(zip(names, post_std.tolist())),
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

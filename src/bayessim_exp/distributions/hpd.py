"""Where a parameter vector lies in a distribution: its HPD level among the distribution's draws (theta lies in
the level-L highest-density region iff its level is below L), and how often level-L regions held their parameters.
The truth's score, the spread's calibration and the coverage diagnostics all read these."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from .base import ParameterDistribution
from .mixture_stack import MixtureStack


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


def own_levels(posteriors: MixtureStack | Sequence[ParameterDistribution], theta: torch.Tensor, draws: int,
               generator: torch.Generator) -> torch.Tensor:
    """[own_level(posterior, t, draws, generator) for each posterior and its theta [S, D]] as float64 [S]: a
    MixtureStack's in one batched pass that consumes the generator as the loop over its members would (each member's
    draws, then its tie-break where theta has density), so the levels are the loop's to rounding."""
    if not isinstance(posteriors, MixtureStack):
        return torch.tensor([own_level(p, t, draws, generator) for p, t in zip(posteriors, theta)], dtype=torch.float64)
    at_theta = posteriors.log_prob(theta.double()[:, None])[:, 0]
    comps, noise, tie_breaks = [], [], torch.zeros(len(theta), dtype=torch.float64)
    for s in range(len(theta)):
        comp, eps = posteriors.noise(s, draws, generator)
        comps.append(comp)
        noise.append(eps)
        if math.isfinite(float(at_theta[s])):
            tie_breaks[s] = float(torch.rand(1, generator=generator, dtype=torch.float64))
    lp = posteriors.log_prob(posteriors.draws(torch.stack(comps), torch.stack(noise)))  # [S, draws]
    levels = ((lp > at_theta[:, None]).double().mean(1) + tie_breaks * (lp == at_theta[:, None]).double().mean(1))
    return torch.where(torch.isfinite(at_theta), levels, 1.0)


def shares_inside(levels_of: torch.Tensor, levels) -> dict[str, float]:
    """{level: share of the HPD levels `levels_of` below it}: how often the level-L regions held their parameters."""
    return {f"{level:g}": float((levels_of < level).double().mean()) for level in levels}

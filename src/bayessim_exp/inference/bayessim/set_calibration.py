"""The temperature of the product over several real trajectories, fitted on simulated sets of as many.

With n real trajectories the posterior is p(theta) prod_i q(theta | x_i) / p~(theta) (correction.py): exact if
q is, and q's errors multiply. A model whose single-trajectory posteriors are calibrated (its spread fitted
on held-out pairs, models/mdnn.py) can still give products that are far too narrow: diagonal components
that miss the parameters' correlations, or a width slightly off in every factor, compound with n.
Measured on Cartpole (13 parameters, 50 truths drawn from the prior, docs/statistics.md): the final
posterior held the truth in its 90 % region for 0.90 of the truths after round 1 and 0.28 after round 3.

The remedy is a temperature for the product, fitted where its error shows: sets of n trajectories simulated at
one parameter value each (the round's held-out draws from its proposal), each set conditioned exactly as the
real set is at temperatures tau (the likelihood ratios raised to tau), and the tau kept whose sets hold their
own parameters inside their level-L HPD regions closest to the share L, at every reported level L (the sum of
squared deviations in standard errors). It only ever widens (tau <= 1).

Why coverage and not the mean log density (a proper score): the products' errors are heavier-tailed than
one temperature can follow, so the best log score widens the core to reach the tails. On Pendulum's sets
it chose tau = 0.71, where the 50 % regions held 0.63 of the sets (and the calibration study 0.62 of its
truths); tau = 1 held 0.51 and 0.85 at 90 %. Matching both levels lands in between.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch

from ...distributions.base import ParameterDistribution
from ...distributions.hpd import own_levels, shares_inside
from ...distributions.mixture_stack import MixtureStack

COARSE = tuple(2.0 ** (-k / 2) for k in range(9))  # 1 down to 1/16 in steps of sqrt(2)
_FINE_STEPS = (-3, -2, -1, 1, 2, 3)  # then eighths of a doubling around the best coarse one
# A set's posterior without a closed form is importance-sampled (correction.py) at every temperature tried: its pool
# only has to give the `draws` that locate the set's own parameters, so it is this many times `draws` (a pool of
# method.importance_draws for each of some thousand sets and temperatures was most of a round's time: docs/benchmarks.md).
POOL_PER_DRAW = 20
# the sets' posteriors at one temperature: a MixtureStack, read all at once, or one posterior per set
SetPosteriors = MixtureStack | list[ParameterDistribution]


def set_importance_draws(importance_draws: int, draws: int) -> int:
    """The importance pool of a simulated set's posterior: POOL_PER_DRAW x the `draws` read from it, at most the
    real data's `importance_draws`."""
    return min(importance_draws, POOL_PER_DRAW * draws)


def miscalibration(levels_of_sets: torch.Tensor, levels: Sequence[float]) -> float:
    """Sum over `levels` L of ((share of sets whose HPD level is below L) - L)^2 / (L (1 - L) / sets): a
    chi-square-like distance from calibration, each level's deviation in its own binomial standard errors."""
    k = len(levels_of_sets)
    return sum(float((levels_of_sets < level).double().mean() - level) ** 2 / (level * (1 - level) / k)
               for level in levels)


def product_temperature(levels_at: Callable[[float], torch.Tensor], levels: Sequence[float]) -> tuple[float, dict]:
    """(tau, record): levels_at(tau) gives each simulated set's HPD level of its own parameters [K] (1 where
    the posterior puts no density there); tau minimises `miscalibration` over COARSE, then over eighths of a
    doubling around the best, ties to the larger tau (the narrower posterior). The shares inside grow as tau
    falls, so the distance falls and then rises: the coarse descent stops two steps past its lowest."""
    tried: dict[float, torch.Tensor] = {}

    def key(tau: float) -> tuple[float, float]:
        if tau not in tried:
            tried[tau] = levels_at(tau).double()
        return miscalibration(tried[tau], levels), -tau

    best = COARSE[0]
    for i, tau in enumerate(COARSE):
        if key(tau) < key(best):
            best = tau
        elif i - COARSE.index(best) >= 2:
            break
    fine = [best * 2.0 ** (step / 8) for step in _FINE_STEPS]
    best = min([best, *(tau for tau in fine if COARSE[-1] <= tau <= 1)], key=key)
    return best, {"temperature": best, "sets": len(tried[best]),
                  "inside": {f"{tau:.4g}": shares_inside(values, levels) for tau, values in sorted(tried.items(), reverse=True)}}


def simulated_sets_temperature(theta: torch.Tensor, n: int,
                               simulate: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
                               products_of: Callable[[torch.Tensor], Callable[[float], SetPosteriors]],
                               levels: Sequence[float], draws: int, seed: int) -> tuple[float, dict]:
    """`product_temperature` fitted on one set of n simulations at each of theta [K, D] (the round's held-out
    parameters), sets with a failed simulation left out. simulate(theta [M, D]) -> (kept [M], summaries [M, F])
    driven as the real data were; products_of(summaries [K', n, F]) -> the sets' product posteriors as a function of
    the temperature; `draws` per set locate its own parameters' HPD level."""
    count = len(theta)
    kept, x = simulate(theta.repeat_interleave(n, 0))
    ok = kept.reshape(count, n).all(1)
    theta, x = theta[ok], x.reshape(count, n, -1)[ok]
    products = products_of(x)

    def levels_at(temperature: float) -> torch.Tensor:
        generator = torch.Generator().manual_seed(seed)  # the same draws' stream at every temperature
        return own_levels(products(temperature), theta, draws, generator)

    return product_temperature(levels_at, levels)

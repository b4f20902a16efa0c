"""Coverage where the real data put the posterior: is the model calibrated there, not only on average?

A round's held-out coverage (coverage.py) averages over its proposal. A model can pass it and still be off in
the small region the real data point to: on ShadowHand (docs/benchmarks.md) every round's held-out 90 %
coverage lay in 0.86-0.90 while the palm's mass sat 5-10 posterior standard deviations below the truth.

The check: draw theta_j from the posterior given the real trajectories, simulate one trajectory x_j at each,
and place theta_j in the posterior given the real trajectories and x_j, conditioned exactly as the real
ones are (BayesSim: as their product at the temperature fitted for products of as many on the proposal's
sets, so that what products get wrong on average is not counted again). If the per-trajectory model is exact,
theta_j given (real data, x_j) is distributed as that posterior (the posterior is the prior of x_j), so theta_j
lies in its level-L HPD region with probability L, whatever the prior and wherever the real data lie. A model biased near the real data moves each theta_j's
posterior away from it and the share inside falls. (Placing theta_j in the posterior given x_j alone is not
calibrated even for an exact model: where the prior is informative the posterior shrinks toward it, and
parameters drawn far in its tail fall outside; tests/unit/test_local_coverage.py.)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch

from ..distributions.base import ParameterDistribution
from ..distributions.hpd import own_level, shares_inside


def local_coverage(posterior_given: Callable[[list], ParameterDistribution], real: list,
                   simulate: Callable[[torch.Tensor], tuple[torch.Tensor, list]], count: int,
                   levels: Sequence[float], draws: int, seed: int) -> dict:
    """{"count": pairs used, "hpd": {level: share of theta_j inside their level-L region}}.

    posterior_given(conditionals) -> the posterior given trajectories' per-trajectory posteriors; real: the
    real trajectories' ones; simulate(theta [count, D]) -> (kept [count] bool: simulations that did not
    diverge, the per-trajectory posteriors of the kept ones); draws: posterior draws an HPD level is read from."""
    generator = torch.Generator().manual_seed(seed)
    theta = posterior_given(real).sample((count,), generator=generator).double()
    kept, simulated = simulate(theta)
    if not simulated:
        return {"count": 0, "hpd": None}
    level_of = torch.tensor([own_level(posterior_given([*real, q]), t, draws, generator)
                             for t, q in zip(theta[kept], simulated)], dtype=torch.float64)
    return {"count": len(level_of), "hpd": shares_inside(level_of, levels)}

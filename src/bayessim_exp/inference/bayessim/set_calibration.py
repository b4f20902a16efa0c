"""The temperature of the product over several real trajectories, fitted on simulated sets of as many.

With n real trajectories the posterior is p(theta) prod_i q(theta | x_i) / p~(theta) (correction.py): exact if
q is, and q's errors multiply. A model whose single-trajectory posteriors are calibrated (its spread fitted
on held-out pairs, models/mdnn.py) can still give products that are far too narrow: diagonal components
that miss the parameters' correlations, or a width slightly off in every factor, compound with n.
Measured on Cartpole (13 parameters, 50 truths drawn from the prior, docs/statistics.md): the final
posterior held the truth in its 90 % region for 0.90 of the truths after round 1 and 0.28 after round 3.

The remedy is temperature scaling for the product, fitted where its error shows: sets of n trajectories
simulated at one parameter value each (the round's held-out draws from its proposal), each set conditioned
exactly as the real set is, at temperatures TEMPERATURES (the likelihood ratios raised to tau), and the
tau with the highest mean log density of the sets' own parameters is kept: a proper scoring rule, so tau
stays 1 where the product is right, and it only ever widens (tau <= 1).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

TEMPERATURES = tuple(2.0 ** (-k / 2) for k in range(9))  # 1 down to 1/16 in steps of sqrt(2)
_FLOOR = -1e3  # a set whose posterior puts (numerically) no density at its parameters counts as this


def product_temperature(log_density_at: Callable[[float], torch.Tensor]) -> tuple[float, dict]:
    """(tau, record): log_density_at(tau) gives each simulated set's log posterior density at its own
    parameters [K]; tau maximises their mean over TEMPERATURES."""
    means = {}
    for tau in TEMPERATURES:
        values = log_density_at(tau).double()
        means[tau] = float(torch.where(torch.isfinite(values), values, torch.tensor(_FLOOR, dtype=values.dtype))
                           .clamp_min(_FLOOR).mean())
    best = max(TEMPERATURES, key=lambda tau: (means[tau], tau))
    return best, {"temperature": best, "sets": len(values),
                  "mean_log_density": {f"{tau:.4g}": value for tau, value in means.items() if math.isfinite(value)}}

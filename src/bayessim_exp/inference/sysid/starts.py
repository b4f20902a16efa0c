"""Where the Gauss-Newton runs of a round start, and which one the round keeps.

Gauss-Newton finds the minimum nearest its start; trajectory fits have others (a pendulum swinging in the wrong
phase fits part of the data: seen from the prior's mean, a Pendulum truth of mass 0.6 and length 0.39 sat behind
one, the fit's residual as large as the observations' spread). So a round runs `starts` fits: one from the
previous round's estimate (the prior's mean in round 1), the others from the best of `screen` parameter draws
from the prior, whose residuals cost one batch of simulations; it keeps the fit with the smallest residual.
"""

from __future__ import annotations

import logging

import numpy as np

from ...distributions.base import ParameterDistribution
from ...errors import PosteriorError
from .fit import SysidConfig, SysidFit, fit
from .residual import ReplayResidual

log = logging.getLogger(__name__)


def start_points(residual: ReplayResidual, first: np.ndarray, prior: ParameterDistribution, cfg: SysidConfig,
                 generator) -> list[np.ndarray]:
    """`first` [D] and the cfg.starts - 1 prior draws (unit coordinates) with the smallest residuals."""
    if cfg.starts == 1:
        return [first]
    low, span = residual.low, residual.span
    draws = (prior.sample((cfg.screen,), generator=generator).double().numpy() - low) / span  # [screen, D]
    r = residual(draws.T)  # [R, screen]
    objective = np.where(np.isfinite(r).all(0), 0.5 * (np.nan_to_num(r) ** 2).sum(0), np.inf)
    best = np.argsort(objective)[: cfg.starts - 1]
    return [first, *(draws[i] for i in best if np.isfinite(objective[i]))]


def best_fit(residual: ReplayResidual, names: list[str], starts: list[np.ndarray], cfg: SysidConfig) -> SysidFit:
    """The fit with the smallest residual over runs from every start; a start whose replays diverge is skipped."""
    fits, failures = [], []
    for start in starts:
        try:
            fits.append(fit(residual, names, start, cfg))
        except PosteriorError as exc:
            failures.append(str(exc))
    if not fits:
        raise PosteriorError(f"sysid: no fit from {len(starts)} starts: {'; '.join(failures)}")
    objectives = [f.objectives[-1] for f in fits]
    log.info("sysid: final objectives from %d starts: %s", len(fits), ", ".join(f"{v:.3g}" for v in objectives))
    return fits[int(np.argmin(objectives))]

"""Widening the posterior until the real trajectories lie among its replays: a posterior no narrower than
the simulator's own error allows.

A simulator is never exactly the real system. With deterministic simulations and data from it, the
posterior given n trajectories narrows as n grows, around the parameters that fit best, at a width set
by the density model's accuracy, not by how well any parameter reproduces the data. Data from a
slightly different system (another integrator, another time step) then give a confident posterior
whose replays all lie farther from the real trajectory than they lie from each other
(diagnostics/replayed_check.py: `too_narrow`).

The remedy here is a power posterior: the likelihood ratios of the product over real trajectories
raised to tau (correction.posterior's `temperature`, on top of the dispersion combination's), chosen in
two steps from the replayed check of the posterior at tau = 1:

1. a model-error allowance: the largest tau at which the posterior's covariance (Sigma / tau, as for a
   Gaussian) contains the model error's (ReplayCheck.model_error_covariance: the parameters' spread that what
   the real summaries leave unexplained, feature by feature, allows), capped at the prior's in every direction
   (a parameter the summaries barely see would otherwise send tau to zero for all of them);
2. then halved until no real trajectory's implied parameters lie outside the posterior (`too_narrow`) or
   tau reaches TEMPERATURE_FLOOR.

On data the simulator reproduces, the residual has no excess and tau stays 1 but for the check's false
alarms (alpha per trajectory); where the model error is large against the posterior's width it is
small. docs/statistics.md has the measurements (benchmarks/foreign_dynamics.py).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch

from ...diagnostics.replayed_check import ReplayCheck
from .correction import loewner_min

log = logging.getLogger(__name__)

TEMPERATURE_FLOOR = 2.0**-10  # a thousandth of the data's weight: the prior, for any practical n


def model_error_temperature(check: ReplayCheck, prior_covariance: torch.Tensor) -> float:
    """The largest tau in (0, 1] with Sigma_post / tau >= min(Sigma_error, Sigma_prior) (Loewner order)."""
    error = loewner_min(check.model_error_covariance, prior_covariance)
    chol = torch.linalg.cholesky(check.posterior_covariance + 1e-12 * prior_covariance)
    whitened = torch.linalg.solve_triangular(chol, torch.linalg.solve_triangular(chol, error, upper=False).T,
                                             upper=False)
    largest = float(torch.linalg.eigvalsh(0.5 * (whitened + whitened.T)).max())
    return 1.0 if largest <= 1.0 else max(1.0 / largest, TEMPERATURE_FLOOR)


def temper_to_replays(condition_at: Callable[[float], object], check: Callable[[object], ReplayCheck],
                      prior_covariance: torch.Tensor, floor: float = TEMPERATURE_FLOOR,
                      widen: bool = True) -> tuple[object, ReplayCheck, ReplayCheck, float, list[dict] | None]:
    """(posterior, the replayed check of the posterior before widening, that of the posterior returned,
    temperature, one {temperature, min_p_value} per try; None with widen=False, which only checks).

    condition_at(tau): the posterior with its likelihood ratios raised to tau; check(posterior): the
    replayed check of that posterior; prior_covariance: [D, D] in parameter units."""
    posterior = condition_at(1.0)
    first = result = check(posterior)
    if not widen:
        return posterior, first, result, 1.0, None
    tries = [{"temperature": 1.0, "min_p_value": min(result.p_value)}]
    tau = model_error_temperature(first, prior_covariance)
    if tau < 1.0:
        posterior = condition_at(tau)
        result = check(posterior)
        tries.append({"temperature": tau, "min_p_value": min(result.p_value)})
    while result.too_narrow and tau > floor:
        tau = max(tau / 2, floor)
        posterior = condition_at(tau)
        result = check(posterior)
        tries.append({"temperature": tau, "min_p_value": min(result.p_value)})
    if tau < 1:
        log.info("the real trajectories are not reproduced as closely as the posterior's width implies; widened to "
                 "temperature %.3g (replayed p-values %s)", tau, [round(p, 3) for p in result.p_value])
    return posterior, first, result, tau, tries

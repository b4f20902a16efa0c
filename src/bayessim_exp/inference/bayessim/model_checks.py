"""Does the model know the real data? The model_check stage's reads for the guard: do the real summaries lie among
the training simulations (diagnostics/extrapolation.py), and is the model's product calibrated near them
(diagnostics/local_coverage.py)?"""

from __future__ import annotations

from collections.abc import Callable

import torch

from ...diagnostics.extrapolation import inputs_outside
from ...diagnostics.local_coverage import local_coverage
from ...distributions.base import ParameterDistribution


def extrapolation(model, rounds: list[tuple[torch.Tensor, ...]], fitted_space: Callable[[torch.Tensor], torch.Tensor],
                  x_real: torch.Tensor, alpha: float, seed: int) -> dict:
    """The real summaries among the training ones of `rounds` (each round's training_data.split), in the parameters
    (in the space the model is fitted in) a regression from the model's inputs predicts; the last round's
    held-out summaries set the test's scale."""
    with torch.no_grad():
        train = torch.cat([model.inputs(x_train) for _, x_train, _, _ in rounds])
        theta = fitted_space(torch.cat([theta_train for theta_train, _, _, _ in rounds]))
        return inputs_outside(model.inputs(x_real.reshape(-1, x_real.shape[-1])), train, theta,
                              model.inputs(rounds[-1][3]), alpha, seed=seed)


def coverage_near_real(model, x_real: torch.Tensor, simulate: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
                       product: Callable[[list], ParameterDistribution], sets: int, levels, draws: int,
                       seed: int) -> dict:
    """local_coverage on the model's conditionals given the real summaries x_real [n, F] and one simulated summary
    (simulate(theta [K, D]) -> (kept [K], summaries [K, F])), combined by `product`."""

    def simulated(theta: torch.Tensor) -> tuple[torch.Tensor, list]:
        kept, x = simulate(theta)
        return kept, [model.conditional(x_j.float()) for x_j in x[kept]]

    real = [model.conditional(x.float()) for x in x_real]
    return local_coverage(product, real, simulated, sets, levels, draws, seed)

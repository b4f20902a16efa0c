"""Where a round whose real data lie outside its simulations proposes the next round (method.escape).

Such a round's posterior is an extrapolation and the guard hands an earlier distribution on to domain
randomization; but the next round need not simulate where this one did. `linear`: a ridge regression from the
round's standardised summaries to its parameters in the model's coordinates (probit space by default), read at the
real summaries, with the covariance of its errors on held-out simulations times `INFLATE`: a Gaussian the next
round's proposal is built from as from a posterior (the truncated proposal: the prior restricted to its 99.9 %
region). A linear read extrapolates along the directions the summaries move with the parameters, where a mixture
network's extrapolation collapses onto the box's faces: on Cartpole with its 13 parameters at 1-5 % of their ranges
(a real system in the prior's joint tail) round 1's posterior put cart mass at 0.314 +- 0.006 (true 0.4) and pole
length at 0.5003 +- 0.0008 (true 0.55), and a round proposed from it learned nothing beyond its proposal
(docs/benchmarks.md, "Rounds that escape"). `posterior`: the round's own posterior. `none`: what the round proposed
from, as a round whose model failed.
"""

from __future__ import annotations

import torch

from ...models.base import constant_columns
from ...models.projection import RidgeSystem

ESCAPES = ("linear", "nearest", "posterior", "none")
NEAREST = 0.02  # the share of the fitted simulations whose linear reads lie nearest the real data's (nearest)
PENALTIES = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)  # on standardised summaries, each parameter's by held-out error
INFLATE = 4.0  # the read's error covariance is widened so (twice its standard deviation) that its region holds the truth


def linear_read_at(x_fit: torch.Tensor, u_fit: torch.Tensor, x_check: torch.Tensor, u_check: torch.Tensor,
                   x_real: torch.Tensor, inflate: float = INFLATE, nearest: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean [D], covariance [D, D]) of the parameters u the real summaries x_real [n, F] point to: the ridge
    regression fitted on (x_fit [N, F], u_fit [N, D]), each coordinate's penalty and the error covariance taken on
    (x_check, u_check), read at the mean of the n real summaries' predictions."""
    x_fit, u_fit = x_fit.double(), u_fit.double()
    varying = ~constant_columns(x_fit)
    mean, std = x_fit[:, varying].mean(0), x_fit[:, varying].std(0)

    def design(x: torch.Tensor) -> torch.Tensor:
        z = (x.double()[:, varying] - mean) / std
        return torch.cat([z, torch.ones(len(z), 1, dtype=torch.float64)], 1)

    system = RidgeSystem(design(x_fit)[:, :-1], u_fit)
    weights = torch.stack([system.solve(p) for p in PENALTIES])  # [P, F + 1, D]
    check = design(x_check) @ weights  # [P, M, D]
    best = (check - u_check.double()).pow(2).mean(1).argmin(0)  # [D]
    columns = torch.arange(u_fit.shape[1])
    errors = u_check.double() - check[best, :, columns].T
    read = (design(x_real) @ weights)[best, :, columns].T.mean(0)
    if not nearest:
        return read, inflate * torch.atleast_2d(torch.cov(errors.T))
    reads = (design(x_fit) @ weights)[best, :, columns].T
    distance = ((reads - read) / reads.std(0).clamp_min(1e-12)).pow(2).sum(1)
    near = u_fit[distance.argsort()[:max(2 * u_fit.shape[1], int(NEAREST * len(u_fit)))]]
    return near.mean(0), inflate * torch.atleast_2d(torch.cov(near.T))

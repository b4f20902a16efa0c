"""Where a round whose real data lie outside its simulations proposes the next round (method.escape).

Such a round's posterior is an extrapolation and the guard hands an earlier distribution on to domain randomization;
but the next round need not simulate where this one did. The reads below are Gaussians over the model's coordinates
(probit space by default) that the next round's proposal is built from as from a posterior (the truncated proposal:
the prior restricted to its 99.9 % region). Both start from a ridge regression from the round's standardised
summaries to its parameters (each coordinate's penalty by its error on the held-out simulations):

- `nearest`: the simulations whose regression reads lie nearest the real data's (NEAREST of them;
  semi-automatic ABC's summaries, Fearnhead and Prangle 2012), their mean and covariance times INFLATE. It moves by
  what the simulations show, a step a round: on FrankaCabinet and ShadowHand the truth stayed inside the 90 % region
  of every round it proposed, but two rounds did not reach the real data;
- `linear`: the regression read at the real data, its held-out error covariance times INFLATE, plus the square of
  its distance beyond the range of the parameters it was fitted on (`beyond`; the held-out error says nothing out
  there). It extrapolates: on FrankaCabinet the next round's simulations surrounded the real data, but the hand's
  mass was read on the box's face, four held-out standard deviations past the truth; on ShadowHand the palm's
  mass (0.1 for 1.0), and the next round's posterior missed the truth behind a guard that passed;
- `linear_then_posterior` (the default): `linear` from a round that simulated from anything but a read, the
  round's own posterior from one that simulated from a read: that round's model was trained around its real data,
  where a second linear read extrapolates again from the read's own simulations (ShadowHand: the wrist's and palm's
  masses back on the face);
- `posterior`: the round's own posterior, whose mixture network collapses onto the box's faces out there (Cartpole
  with its parameters at 1-5 % of their ranges: cart mass 0.314 +- 0.006 for 0.4);
- `none`: what the round proposed from, as after a failure of the model itself.

docs/benchmarks.md, "Rounds that escape and focus", has the measurements.
"""

from __future__ import annotations

from typing import Literal

import torch

from ...models.base import constant_columns
from ...models.projection import RidgeSystem

READS = ("linear", "nearest")  # the escapes that read a Gaussian off the real data
Escape = Literal["linear", "nearest", "linear_then_posterior", "posterior", "none"]  # method.escape's choices
NEAREST = 0.02  # the share of the fitted simulations whose linear reads lie nearest the real data's (nearest)
PENALTIES = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)  # on standardised summaries, each parameter's by held-out error
INFLATE = 4.0  # a read's covariance is widened so (twice its standard deviation) that its region holds the truth
# the latest fitted rows the read is fitted on: with thousands of summary features (signatures) the ridge is solved
# in its rows-by-rows dual, and 18,000 rows took 200 s of ShadowHand's guard stage on an H200 machine
MAX_ROWS = 4096


def beyond(read: torch.Tensor, u_fit: torch.Tensor) -> torch.Tensor:
    """[D]: how far the read lies outside the range of the parameters it was fitted on, coordinate by coordinate (0
    inside). The held-out error says nothing out there; the distance is the least the read may be off by."""
    return (read - u_fit.max(0).values).clamp_min(0) + (u_fit.min(0).values - read).clamp_min(0)


def read_at(x_fit: torch.Tensor, u_fit: torch.Tensor, x_check: torch.Tensor, u_check: torch.Tensor,
            x_real: torch.Tensor, inflate: float = INFLATE, nearest: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean [D], covariance [D, D]) of the parameters u the real summaries x_real [n, F] point to: the ridge
    regression fitted on the last MAX_ROWS of (x_fit [N, F], u_fit [N, D]), each coordinate's penalty and the error
    covariance taken on (x_check, u_check), read at the mean of the n real summaries' predictions (`linear`); with
    `nearest`, the mean and covariance of the fitted simulations whose reads lie nearest that one instead."""
    x_fit, u_fit = x_fit[-MAX_ROWS:].double(), u_fit[-MAX_ROWS:].double()
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
        return read, inflate * torch.atleast_2d(torch.cov(errors.T)) + torch.diag(beyond(read, u_fit) ** 2)
    reads = (design(x_fit) @ weights)[best, :, columns].T
    distance = ((reads - read) / reads.std(0).clamp_min(1e-12)).pow(2).sum(1)
    near = u_fit[distance.argsort()[:max(2 * u_fit.shape[1], int(NEAREST * len(u_fit)))]]
    return near.mean(0), inflate * torch.atleast_2d(torch.cov(near.T))

"""Which parameters the run's summaries and collect policy can pin down, before the posterior model is fitted.

Global, from the simulations a round makes anyway: per parameter, the held-out R^2 of a ridge regression from the
standardised summaries to the parameter's fitted coordinate (probit where the model fits in probit space), the share
of its spread under the round's proposal that a linear read of the summaries explains. The best regressor's R^2 is
the expected posterior contraction (E Var(u | x) = Var u (1 - R^2)), so a linear read's is a lower bound on it: a
parameter that acts through an interaction (a pendulum's mass divides the torque) reads low here and still contracts,
which `contraction` in results.json (diagnostics/scoring.py) shows at the end. Pairs that trade off: where the
summaries pin down a combination of two parameters (a product m L, a sum of two dampings) but not each, the held-out
prediction errors of the two correlate; a correlation beyond +-TRADE_OFF names the pair. Both are reported, not
flagged: on the default Pendulum the linear read gives its mass 0.00 and its length 0.15, and the posterior pins both.

Local, at the nominal model (Brun, Reichert and Kuensch 2001, 'Practical identifiability analysis of large
environmental simulation models', Water Resources Research 37): trajectories with the same actions and initial states
at the nominal parameters, each moved by +-STEP of its prior standard deviation in turn; per parameter the
root-mean-square change of the standardised summaries per prior standard deviation. A parameter that moves nothing cannot be identified, whatever the
model; two whose sensitivity vectors are nearly parallel (collinearity index 1 / sqrt(1 - |cos|) of 10 or more, the
lower edge of Brun et al.'s critical 10-15) trade off near the nominal.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from ..models.base import constant_columns
from ..models.projection import RidgeSystem

RIDGE_PENALTIES = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)  # on standardised summaries; the largest all but predicts the mean
HELD_OUT = 0.2  # the last share of the rows, never fitted on
STEP = 0.1  # the local view's central difference, in prior standard deviations
NO_EFFECT = 0.01  # a coordinate whose whole prior spread moves the summaries by less than 1 % of theirs does nothing
COLLINEAR = 10.0  # Brun et al.'s critical collinearity index (10-15): the lower edge
TRADE_OFF = 0.5  # held-out prediction errors correlated beyond this: a pair the summaries tell apart only in part


def held_out_predictions(x: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(predictions, targets) [M, D] on the held-out rows of u [N, D] from x [N, F]: per column, the ridge penalty
    with the smallest held-out error (models/projection.RidgeSystem: intercept unpenalised), computed on x's device
    (thousands of summaries make the normal equations the cost: a GPU forms them in a fraction of a CPU's time).
    x's constant columns are dropped; with none left, the prediction is the fitted rows' mean."""
    x, u = x.double(), u.to(x.device).double()
    held = torch.arange(len(x), device=x.device) >= int((1 - HELD_OUT) * len(x))
    varying = x[:, ~constant_columns(x[~held])]
    if varying.shape[1] == 0:
        return u[~held].mean(0).expand(int(held.sum()), -1), u[held]
    z = (varying - varying[~held].mean(0)) / varying[~held].std(0)
    fitted = RidgeSystem(z[~held], u[~held])  # the normal equations of the fitted rows alone
    design = torch.cat([z[held], torch.ones(int(held.sum()), 1, dtype=z.dtype, device=z.device)], 1)
    predictions = torch.stack([design @ fitted.solve(p) for p in RIDGE_PENALTIES])
    best = (predictions - u[held]).pow(2).mean(1).argmin(0)  # [D]: each parameter's penalty
    return predictions[best, :, torch.arange(u.shape[1], device=x.device)].T, u[held]


def linear_read(x: torch.Tensor, u: torch.Tensor, names: list[str], trade_off: float = TRADE_OFF) -> dict:
    """The global view for summaries x [N, F] of simulations at parameters u [N, D] (the model's coordinates):
    {"pairs": held-out rows, "r2": {name: R^2}, "trade_offs": [{"pair": [a, b], "correlation": c}] with
    |c| >= trade_off, strongest first}."""
    predicted, actual = held_out_predictions(x, u)
    errors = (actual - predicted).cpu()
    actual = actual.cpu()
    r2 = 1 - errors.pow(2).mean(0) / actual.var(0, correction=0).clamp_min(1e-300)
    correlation = torch.corrcoef(errors.T) if len(names) > 1 else torch.ones(1, 1, dtype=errors.dtype)
    pairs = [(float(correlation[i, j]), i, j) for i in range(len(names)) for j in range(i + 1, len(names))
             if abs(float(correlation[i, j])) >= trade_off]
    return {
        "pairs": len(actual),
        "r2": dict(zip(names, r2.tolist())),
        "trade_offs": [{"pair": [names[i], names[j]], "correlation": c}
                       for c, i, j in sorted(pairs, key=lambda p: -abs(p[0]))],
    }


def sensitivity(summaries_at: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]], u0: torch.Tensor,
                scale: torch.Tensor, names: list[str], step: float = STEP, no_effect: float = NO_EFFECT,
                collinearity: float = COLLINEAR) -> dict:
    """The local view at u0 [D] (parameters in prior standard deviations). `summaries_at(points [K, D])` -> (summaries [K, M, F], kept
    [M]: trajectories neither diverged nor with non-finite summaries at every point), the same M actions and initial
    states at every point; `scale` [F]: each summary's spread over the round's simulations.
    {"trajectories": M kept, "rms": {name: RMS change of x / scale per unit of u}, "no_effect": names with rms below
    `no_effect`, "collinear": [{"pair": [a, b], "cosine": c, "index": 1 / sqrt(1 - |c|)}] with index >= collinearity}."""
    d = len(names)
    moves = step * torch.eye(d, dtype=torch.float64)
    x, kept = summaries_at(torch.cat([u0[None] + moves, u0[None] - moves]))
    x = x[:, kept].double() / scale.double()
    effect = ((x[:d] - x[d:]) / (2 * step)).reshape(d, -1)  # [D, M F]
    rms = effect.pow(2).mean(1).sqrt() if effect.shape[1] else torch.zeros(d, dtype=torch.float64)
    unit = effect / effect.norm(dim=1, keepdim=True).clamp_min(1e-300)
    cosine = unit @ unit.T
    pairs = []
    for i in range(d):
        for j in range(i + 1, d):
            c = float(cosine[i, j])
            index = 1 / max(1 - abs(c), 1e-12) ** 0.5
            if index >= collinearity and rms[i] >= no_effect and rms[j] >= no_effect:
                pairs.append({"pair": [names[i], names[j]], "cosine": c, "index": index})
    return {
        "trajectories": int(kept.sum()),
        "rms": dict(zip(names, rms.tolist())),
        "no_effect": [n for n, v in zip(names, rms.tolist()) if v < no_effect],
        "collinear": sorted(pairs, key=lambda p: -p["index"]),
    }

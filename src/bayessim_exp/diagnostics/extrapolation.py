"""Real data where the model saw no simulations: its posterior there is an extrapolation.

A model trained on simulations from a proposal is checked (held-out coverage) where those simulations lie.
A real summary whose model inputs (`PosteriorModel.inputs`: standardised summaries, or their ridge
predictions of the parameters) lie far from every training input gets a posterior the checks never saw,
and it can be confidently wrong: a real system in the joint tail of the prior (ShadowHand's surrogate hand,
every mass scaled alike) is mapped to where the training simulations were (docs/statistics.md, "Real data
outside the simulations").

"Far" is measured where the inputs speak about the parameters: a ridge regression from the training inputs to
the parameters (models/projection.py, as the projected models' own inputs) predicts them for every summary, and
each real prediction's squared Mahalanobis distance from the training predictions (their mean and covariance)
is its statistic. Raw summaries have directions in which the simulator hardly varies (relations between
consecutive states that its integrator fixes); a real system integrated otherwise lies far out in them, although
the posterior hardly depends on them (benchmarks/foreign_dynamics.py: a pendulum integrated by RK4).

The p-value is the share (1 + #held-out simulations as far or farther) / (held-out + 1), exact (uniform) when
the real summary is exchangeable with the round's held-out simulations, whatever their distribution. With n real
summaries a round is flagged when one p-value is below alpha / n (Bonferroni: at most alpha under any dependence
between them, such as one hidden parameter vector shared by all).
"""

from __future__ import annotations

import torch

from ..models.projection import RidgeProjection


def _cholesky(cov: torch.Tensor, scale: float) -> torch.Tensor:
    """The covariance's Cholesky factor, with the least jitter (from 1e-9 of the mean variance) that makes it
    positive definite: predictions that are linear combinations of others."""
    jitter = 1e-9
    while jitter <= 1:
        factor, info = torch.linalg.cholesky_ex(cov + jitter * scale * torch.eye(len(cov), dtype=cov.dtype))
        if int(info) == 0:
            return factor
        jitter *= 100
    raise ValueError("the training simulations' parameter predictions have no finite covariance")


@torch.no_grad()
def inputs_outside(real: torch.Tensor, train: torch.Tensor, train_theta: torch.Tensor, held: torch.Tensor,
                   alpha: float, seed: int = 0) -> dict:
    """real [n, E], train [m, E], held [k, E]: model inputs of the real summaries, of the training simulations
    (whose parameters, in the model's fitted space, are train_theta [m, D]) and of the round's held-out ones.
    Returns {"distance": [n] squared Mahalanobis distances of the parameter predictions, "p_value": [n],
    "min_p_value", "held_out_median": the held-out distances' median, "alpha", "flagged": indices with
    p < alpha / n}. With k held-out simulations no p-value is below 1 / (k + 1): n >= alpha (k + 1) real
    summaries cannot be flagged."""
    theta = train_theta.double()
    projection = RidgeProjection(train.shape[1], theta.shape[1])
    reference = projection.fit(train.float(), ((theta - theta.mean(0)) / theta.std(0).clamp_min(1e-12)).float(),
                               seed).double()  # out of fold: predicted as the held-out and real summaries are
    mean, var = reference.mean(0), reference.var(0)
    factor = _cholesky(torch.cov(reference.T).reshape(len(mean), len(mean)), float(var.mean()))

    def distance(x: torch.Tensor) -> torch.Tensor:
        return torch.linalg.solve_triangular(factor, (projection(x.float()).double() - mean).T, upper=False).pow(2).sum(0)

    null, observed = distance(held), distance(real)
    p_values = [(1 + int((null >= d).sum())) / (len(null) + 1) for d in observed]
    n = len(p_values)
    return {"distance": observed.tolist(), "p_value": p_values, "min_p_value": min(p_values),
            "held_out_median": float(null.median()),
            "alpha": alpha, "flagged": [i for i, p in enumerate(p_values) if p < alpha / n]}

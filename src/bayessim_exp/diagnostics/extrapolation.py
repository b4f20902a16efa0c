"""Real data where the model saw no simulations: its posterior there is an extrapolation.

A model trained on simulations from a proposal is checked (held-out coverage) where those simulations lie.
A real summary whose model inputs (`PosteriorModel.inputs`: standardised summaries, or their ridge
predictions of the parameters) lie far from every training input gets a posterior the checks never saw,
and it can be confidently wrong: a real system in the joint tail of the prior (ShadowHand's surrogate hand,
every mass scaled alike) is mapped to where the training simulations were (docs/statistics.md, "Real data
outside the simulations").

The statistic is each real input's Mahalanobis distance from the training inputs (their mean and covariance);
its p-value is the share (1 + #held-out inputs as far or farther) / (held-out + 1), exact (uniform) when the
real summary is exchangeable with the round's held-out simulations, whatever the inputs' distribution. With n
real summaries a round is flagged when one p-value is below alpha / n (Bonferroni: at most alpha under any
dependence between them, such as one hidden parameter vector shared by all).
"""

from __future__ import annotations

import torch

# above this many inputs the covariance is left out (per-input standardisation): its factorisation would cost
# more than the fit (raw signature summaries have thousands of features)
MAX_FULL_COVARIANCE = 2048


def _cholesky(cov: torch.Tensor, scale: float) -> torch.Tensor:
    """The covariance's Cholesky factor, with the least jitter (from 1e-9 of the mean variance) that makes it
    positive definite: inputs that are linear combinations of others (a constant feature, collinear ones)."""
    jitter = 1e-9
    while jitter <= 1:
        factor, info = torch.linalg.cholesky_ex(cov + jitter * scale * torch.eye(len(cov), dtype=cov.dtype))
        if int(info) == 0:
            return factor
        jitter *= 100
    raise ValueError("the training simulations' model inputs have no finite covariance")


def inputs_outside(real: torch.Tensor, train: torch.Tensor, held: torch.Tensor, alpha: float) -> dict:
    """real [n, E], train [m, E], held [k, E]: model inputs of the real summaries, of the training simulations
    and of the round's held-out ones. Returns {"distance": [n] squared Mahalanobis distances, "p_value": [n],
    "min_p_value", "held_out_median": the held-out distances' median, "alpha", "flagged": indices with
    p < alpha / n}. With k held-out simulations no p-value is below 1 / (k + 1): n >= alpha (k + 1) real
    summaries cannot be flagged."""
    train, held, real = train.double(), held.double(), real.double()
    mean = train.mean(0)
    var = train.var(0).clamp_min(1e-12)
    if train.shape[1] <= MAX_FULL_COVARIANCE:
        factor = _cholesky(torch.cov(train.T).reshape(train.shape[1], train.shape[1]), float(var.mean()))

        def distance(x: torch.Tensor) -> torch.Tensor:
            return torch.linalg.solve_triangular(factor, (x - mean).T, upper=False).pow(2).sum(0)
    else:
        def distance(x: torch.Tensor) -> torch.Tensor:
            return ((x - mean).pow(2) / var).sum(1)

    null, observed = distance(held), distance(real)
    p_values = [(1 + int((null >= d).sum())) / (len(null) + 1) for d in observed]
    n = len(p_values)
    return {"distance": observed.tolist(), "p_value": p_values, "min_p_value": min(p_values),
            "held_out_median": float(null.median()),
            "alpha": alpha, "flagged": [i for i, p in enumerate(p_values) if p < alpha / n]}

"""Combining several real trajectories: the product of per-trajectory posteriors, tempered when they disagree.

`product`: p(theta) prod_i q(theta | x_i) / p~(theta) (correction.py), exact when q is.
`dispersion` (default): the same product with the likelihood ratios raised to tau = 1 / max(1, B),
where B is the Birge ratio of the per-trajectory posteriors (Cochran's Q over its degrees of freedom,
as in meta-analysis and the PDG's scale factor S = sqrt(B)):

    Q = sum_i (m_i - m)^T C_i^-1 (m_i - m),   m = (sum_i C_i^-1)^-1 sum_i C_i^-1 m_i,   B = Q / (D (n - 1)),

m_i, C_i the mean and covariance of the posterior given trajectory i alone. If each of those were
exact (and close to Gaussian), Q would follow chi^2 with D (n - 1) degrees of freedom, B would be
near 1 and tau = 1 leaves the product alone. Per-trajectory posteriors that scatter more than their
widths allow (q too narrow where it extrapolates, or data the simulator cannot reproduce) give B > 1,
and tempering widens the combined posterior by about sqrt(B), as a quasi-likelihood does with
overdispersed data. docs/statistics.md has the measurements behind the default.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from typing import Literal, get_args

import torch

from .correction import IMPORTANCE_DRAWS, MAX_COMPONENTS, moments, posterior

log = logging.getLogger(__name__)

Combination = Literal["dispersion", "product"]  # method.combination's choices
COMBINATIONS = get_args(Combination)


@dataclasses.dataclass
class Dispersion:
    """Agreement of the per-trajectory posteriors: Cochran's Q, its degrees of freedom and chi^2 p-value,
    the Birge ratio Q / dof and the temperature it implies."""

    q: float
    dof: int
    p_value: float

    @property
    def birge_ratio(self) -> float:
        return self.q / self.dof

    @property
    def temperature(self) -> float:
        return 1.0 / max(1.0, self.birge_ratio)

    def record(self) -> dict:
        return {"cochran_q": self.q, "dof": self.dof, "p_value": self.p_value, "birge_ratio": self.birge_ratio,
                "temperature": self.temperature}


def dispersion(singles: Sequence, seed: int = 0) -> Dispersion:
    """Cochran's Q of posteriors given one trajectory each (n >= 2), from their sampled moments."""
    means, precisions = [], []
    for post in singles:
        mean, cov = moments(post, seed)
        means.append(mean.double())
        cov = cov.double()
        precisions.append(torch.linalg.inv(cov + 1e-12 * cov.diagonal().mean() * torch.eye(len(cov), dtype=cov.dtype)))
    m_i, p_i = torch.stack(means), torch.stack(precisions)
    pooled = torch.linalg.solve(p_i.sum(0), (p_i @ m_i.unsqueeze(-1)).sum(0)).squeeze(-1)
    d = m_i - pooled
    q = float((d.unsqueeze(-2) @ p_i @ d.unsqueeze(-1)).sum())
    dof = m_i.shape[1] * (len(singles) - 1)
    # the chi^2 survival function is the regularised upper incomplete gamma function
    return Dispersion(q, dof, float(torch.special.gammaincc(torch.tensor(dof / 2.0), torch.tensor(q / 2.0))))


def combine(method: str, conditionals: Sequence, prior, proposal=None, *, max_components: int = MAX_COMPONENTS,
            seed: int = 0, temperature: float = 1.0,
            importance_draws: int = IMPORTANCE_DRAWS) -> tuple[object, Dispersion | None]:
    """The posterior given every real summary's conditional q(theta | x_i), and the dispersion of the
    per-trajectory posteriors (None for a single trajectory). `temperature` in (0, 1] multiplies the
    one the combination chooses (the replayed check's widening, inference/bayessim/replay_tempering.py)."""
    if method not in COMBINATIONS:
        raise ValueError(f"combination {method!r} not allowed; allowed: {', '.join(COMBINATIONS)}")
    if len(conditionals) == 1:
        return posterior(conditionals, prior, proposal, max_components=max_components, seed=seed,
                         temperature=temperature, importance_draws=importance_draws), None
    proposals = list(proposal) if isinstance(proposal, (list, tuple)) else [proposal] * len(conditionals)
    singles = [posterior([q], prior, p, max_components=max_components, seed=seed, importance_draws=importance_draws)
               for q, p in zip(conditionals, proposals)]
    spread = dispersion(singles, seed)
    tau = spread.temperature if method == "dispersion" else 1.0
    if spread.birge_ratio > 1.0 and temperature == 1.0:
        log.info("real trajectories disagree beyond their posteriors' widths: Birge ratio %.2f (chi2 p = %.2g)%s",
                 spread.birge_ratio, spread.p_value, f"; tempering by {tau:.3f}" if tau < 1 else "")
    return posterior(conditionals, prior, proposal, max_components=max_components, seed=seed,
                     temperature=tau * temperature, importance_draws=importance_draws), spread

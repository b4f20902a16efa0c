"""The spread of a fitted Gaussian-mixture posterior, calibrated on validation pairs in two steps.

1. One factor per parameter on every component's standard deviations, by maximum likelihood (models/mdnn.py):
   temperature scaling per output (Guo et al. 2017). It sets each parameter's marginal.
2. One common factor on all of them, set by where the pairs' own parameters lie in their HPD regions
   (`joint_factor`): the smallest at which the 50 % and 90 % regions hold their share of the pairs, up to one
   binomial standard error (a calibrated model is not widened for its pairs' chance shortfall); below 1 only where
   both regions hold more than their share by more than that, and then no further than both still hold their
   share (the pipeline test's Pendulum seed 2, round 2: 0.60 / 0.92 of its validation pairs at 1). It sets the
   joint. In D dimensions the level-L HPD region of a Gaussian holds theta iff a squared distance with
   mean D and spread sqrt(2 D) lies below its L quantile. A few per cent too little spread in every direction,
   which the marginals hardly show, empties the joint regions: in 102 dimensions 2 % moves the 50 % region's
   share by 0.10. ShadowHand_more's later rounds (docs/statistics.md) held 0.17-0.43 of their held-out
   parameters in the 50 % regions and 0.78-0.84 in the 90 % ones, while every parameter's central intervals
   covered 0.48-0.51 and 0.88-0.90.
   One factor cannot fix the regions' shape. Where the tails are too light and the core about right (held-out
   shares like 0.52 / 0.84), the 90 % region sets it and the 50 % one is left a little wide; where one region is
   too wide and the other right, it stays at 1: an underconfident region is a finding, an overconfident one a
   failure (diagnostics/guard.py).
   A mixture truncated to a box (box space, models/box_mass.py) is read as such: inside the box its regions are the
   untruncated mixture's density levels, weighed by the truncated mixture's own mass (`_box_levels`); the factor
   only narrows it (`joint_factor`).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ..distributions.hpd import shares_inside
from .box_mass import TruncatedMixtureBatch

JOINT_LEVELS = (0.5, 0.9)  # the regions the common factor calibrates (those the guard and the studies read)
JOINT_ROWS = 1000  # validation pairs to fit it on (the caller's cut): a share's standard error at 90 % is 0.01
_JOINT_DRAWS = 500  # posterior draws per pair that place its parameters in their HPD region
_FACTORS = 1.01 ** torch.arange(140)  # tried in steps of 1 %, 1 up to 4
_NARROWER = 1.01 ** -torch.arange(1, 70)  # and below 1 down to one half
_CHUNK_ELEMENTS = 1 << 24  # numbers held per chunk of pairs (draws x components x parameters)
Box = tuple[torch.Tensor, torch.Tensor]  # (low, high) [D]


class SpreadScale(nn.Module):
    """log of the factors on q's standard deviations per standardised parameter (0: as trained)."""

    def __init__(self, dim: int):
        super().__init__()
        self.register_buffer("log_scale", torch.zeros(dim))

    def scale_factors(self, U: torch.Tensor, log_scale: torch.Tensor | None = None) -> torch.Tensor:
        """Precision factors of the rescaled components: U diag(1 / scale), still upper triangular."""
        return U * torch.exp(-(self.log_scale if log_scale is None else log_scale))


@torch.no_grad()
def joint_factor(log_weights: torch.Tensor, means: torch.Tensor, factors: torch.Tensor, theta: torch.Tensor, *,
                 diagonal: bool, seed: int, box: Box | None = None) -> tuple[float, dict]:
    """(c, record): the common factor c on the standard deviations of the mixtures q_n (log weights [N, M], means
    [N, M, D], upper-triangular precision factors [N, M, D, D], diagonal ones where `diagonal`), in steps of 1 %
    from 1/2 to 4: the smallest c >= 1 whose level-L HPD regions hold the share L of the theta_n [N, D] less one
    binomial standard error at every L of JOINT_LEVELS; where at 1 every region holds more than L plus that error,
    the smallest c < 1 at which every region still holds L. The record has the shares at 1 and at c.
    _JOINT_DRAWS draws per pair, the same draws at every c. `box` (low, high [D], the means' units): the
    mixtures truncated to it (theta inside it), only ever narrowed: where a component's mean lies far outside the
    box, widening grows its tail's mass inside by orders of magnitude and can empty the regions instead (a Pendulum
    round 2 held 0.92 of its pairs in the 90 % regions at 1 and 0.79 at 4)."""
    levels_at = _levels_function(log_weights, means, factors, theta, diagonal, seed, box)
    count = len(theta)
    error = {level: math.sqrt(level * (1 - level) / count) for level in JOINT_LEVELS}
    unscaled = shares_inside(levels_at(1.0), JOINT_LEVELS)
    if all(unscaled[f"{level:g}"] > level + error[level] for level in JOINT_LEVELS):
        c, inside = 1.0, unscaled
        for narrower in _NARROWER.tolist():
            shares = shares_inside(levels_at(narrower), JOINT_LEVELS)
            if any(shares[f"{level:g}"] < level for level in JOINT_LEVELS):
                break
            c, inside = narrower, shares
        return c, {"pairs": count, "inside_unscaled": unscaled, "inside": inside}
    if box is not None:  # widened, a truncated mixture's mass inside moves to its components centred outside the box
        return 1.0, {"pairs": count, "inside_unscaled": unscaled, "inside": unscaled}
    for c in _FACTORS.tolist():
        inside = unscaled if c == 1.0 else shares_inside(levels_at(c), JOINT_LEVELS)
        if all(inside[f"{level:g}"] >= level - error[level] for level in JOINT_LEVELS):
            break
    return c, {"pairs": count, "inside_unscaled": unscaled, "inside": inside}


@torch.no_grad()
def member_shares(log_weights: torch.Tensor, means: torch.Tensor, factors: torch.Tensor, theta: torch.Tensor,
                  members: int, *, diagonal: bool, seed: int, box: Box | None = None) -> list[dict[str, float]]:
    """Per member of an ensemble, whose mixture is its members' mixtures side by side (equal blocks of components,
    as joint_factor takes them): the shares of the theta_n inside that member's own HPD regions at JOINT_LEVELS
    (its components alone, their weights renormalised). A member far narrower than the others, wrong, puts its
    weight's share of the ensemble's draws above the density of every theta it misses, a shape no common factor
    repairs (ShadowHand_more, docs/statistics.md); this tells such a member apart."""
    shares = []
    for block in torch.arange(means.shape[1], device=means.device).chunk(members):
        levels_at = _levels_function(torch.log_softmax(log_weights[:, block], -1), means[:, block], factors[:, block],
                                     theta, diagonal, seed, box)
        shares.append(shares_inside(levels_at(1.0), JOINT_LEVELS))
    return shares


def _levels_function(log_w, means, U, theta, diagonal: bool, seed: int, box: Box | None):
    """c -> the HPD level of each theta_n in q_n with every standard deviation multiplied by c [N]."""
    args = log_w.float(), means.float(), U.float(), theta.float(), diagonal, seed
    if box is None:
        terms = _quadratic_terms(*args)
        return lambda c: _levels_at(c, *terms)
    terms = _box_terms(*args, tuple(bound.to(means).float() for bound in box))
    return lambda c: _box_levels(c, *terms)


def _quadratic_terms(log_w, means, U, theta, diagonal: bool, seed: int) -> tuple[torch.Tensor, ...]:
    """What the HPD levels at every factor c are computed from. A draw y = mu_k + c U_k^-1 eps of component k,
    seen from component m: U_m (y - mu_m) / c = a / c + b with a = U_m (mu_k - mu_m), b = U_m U_k^-1 eps, so
    |.|^2 = |a|^2 / c^2 + 2 a.b / c + |b|^2; theta's is |U_m (theta - mu_m)|^2 / c^2. The log determinants
    shift by -D log c for every point alike. Returns (base [N, M]: log weight + log det U_m, A, B, C [N, S, M],
    T [N, M])."""
    n, k, d = means.shape
    generator = torch.Generator().manual_seed(seed)
    component = torch.multinomial(log_w.exp().cpu().double(), _JOINT_DRAWS, replacement=True,
                                  generator=generator).to(means.device)  # [N, S]
    eps = torch.randn(n, _JOINT_DRAWS, d, generator=generator).to(means.device)
    diag = torch.diagonal(U, dim1=-2, dim2=-1)  # [N, M, D]
    base = log_w + torch.log(diag).sum(-1)
    parts: list[list[torch.Tensor]] = [[], [], [], []]
    chunk = max(1, _CHUNK_ELEMENTS // (_JOINT_DRAWS * k * d))
    for r in torch.arange(n, device=means.device).split(chunk):
        mu, Ur, comp, e = means[r], U[r], component[r], eps[r]
        mu_drawn = torch.gather(mu, 1, comp[..., None].expand(-1, -1, d))  # [n, S, D]
        whitened = torch.zeros_like(e)  # U_k^-1 eps of each draw's own component
        for m in range(k):
            if diagonal:
                own = e / diag[r, m][:, None]
            else:
                own = torch.linalg.solve_triangular(Ur[:, m], e.transpose(1, 2), upper=True).transpose(1, 2)
            whitened = torch.where((comp == m)[..., None], own, whitened)
        A, B, C, T = [], [], [], []
        for m in range(k):
            if diagonal:
                a, b = diag[r, m][:, None] * (mu_drawn - mu[:, m, None]), diag[r, m][:, None] * whitened
                t = diag[r, m] * (theta[r] - mu[:, m])
            else:
                a = torch.einsum("nij,nsj->nsi", Ur[:, m], mu_drawn - mu[:, m, None])
                b = torch.einsum("nij,nsj->nsi", Ur[:, m], whitened)
                t = torch.einsum("nij,nj->ni", Ur[:, m], theta[r] - mu[:, m])
            A.append((a * a).sum(-1))
            B.append((a * b).sum(-1))
            C.append((b * b).sum(-1))
            T.append((t * t).sum(-1))
        for part, values in zip(parts, (A, B, C)):
            part.append(torch.stack(values, -1))
        parts[3].append(torch.stack(T, -1))
    return (base, *(torch.cat(p) for p in parts))


def _levels_at(c: float, base, A, B, C, T) -> torch.Tensor:
    """HPD level of each theta_n in q_n with every standard deviation multiplied by c: [N]."""
    at_draws = torch.logsumexp(base[:, None] - 0.5 * (A / c**2 + 2 * B / c + C), -1)  # [N, S]
    at_theta = torch.logsumexp(base - 0.5 * T / c**2, -1)  # [N]
    return (at_draws > at_theta[:, None]).double().mean(1).cpu()


def _quadratic(U: torch.Tensor, diff: torch.Tensor, diagonal: bool) -> torch.Tensor:
    """|U (y - mu)|^2 [n, S] of differences diff [n, S, D] under one component's factors U [n, D, D] (diagonal: [n, D])."""
    if diagonal:
        return ((U[:, None] * diff) ** 2).sum(-1)
    return (torch.einsum("nij,nsj->nsi", U, diff) ** 2).sum(-1)


def _box_terms(log_w, means, U, theta, diagonal: bool, seed: int, box: Box) -> tuple[torch.Tensor, ...]:
    """What a truncated mixture's HPD levels at every factor c are computed from: fixed draws y from a defensive
    proposal g, half the truncated mixture at c = 1 (models/box_mass.py's sampler, which reaches the box's mass of a
    mixture whose means lie far outside it) and half uniform on the box (for the other factors). At factor c a draw
    weighs q_c(y) / g(y) (the truncated mixture's normaliser cancels). Returns (base [N, M]: log weight + log det U_m,
    Q [N, S, M]: |U_m (y - mu_m)|^2, T [N, M]: theta's, log g [N, S])."""
    n, k, d = means.shape
    low, high = box
    generator = torch.Generator().manual_seed(seed)
    half = _JOINT_DRAWS // 2
    # on the CPU, where MixtureBatch draws
    truncated = TruncatedMixtureBatch(log_w.cpu(), means.cpu(), U.cpu(), low.cpu(), high.cpu(), diagonal=diagonal)
    drawn = truncated.sample(half, generator).to(means)  # [S/2, N, D]
    uniform = low + (high - low) * torch.rand(_JOINT_DRAWS - half, n, d, generator=generator).to(means)
    y = torch.cat([drawn, uniform])  # [S, N, D]
    log_g = torch.logaddexp(truncated.log_prob(y.cpu()).to(means), -torch.log(high - low).sum()) - math.log(2)
    y = y.transpose(0, 1)  # [N, S, D]
    diag = torch.diagonal(U, dim1=-2, dim2=-1)  # [N, M, D]
    base = log_w + torch.log(diag).sum(-1)
    parts: list[list[torch.Tensor]] = [[], []]
    chunk = max(1, _CHUNK_ELEMENTS // (_JOINT_DRAWS * k * d))
    for r in torch.arange(n, device=means.device).split(chunk):
        mu, factors = means[r], diag[r] if diagonal else U[r]
        parts[0].append(torch.stack([_quadratic(factors[:, m], y[r] - mu[:, m, None], diagonal) for m in range(k)], -1))
        parts[1].append(torch.stack([_quadratic(factors[:, m], (theta[r] - mu[:, m])[:, None], diagonal)[:, 0]
                                     for m in range(k)], -1))
    return base, *(torch.cat(p) for p in parts), log_g.T


def _box_levels(c: float, base, Q, T, log_g) -> torch.Tensor:
    """HPD level of each theta_n in q_n truncated to the box, every standard deviation multiplied by c: [N], the
    share of the truncated mixture's mass denser than theta, by self-normalised importance weights."""
    # log q_c up to its normaliser's -D log c - D/2 log 2 pi, alike for every draw: it cancels in the weights
    at_draws = torch.logsumexp(base[:, None] - 0.5 * Q / c**2, -1)  # [N, S]
    at_theta = torch.logsumexp(base - 0.5 * T / c**2, -1)  # [N]
    weight = torch.softmax(at_draws - log_g, -1)
    return (weight * (at_draws > at_theta[:, None])).sum(-1).double().cpu()

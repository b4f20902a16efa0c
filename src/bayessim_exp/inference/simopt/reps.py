"""REPS on a Gaussian search distribution: sample weights from the dual, then a KL-bounded Gaussian step.

Episodic REPS (Peters, Muelling & Altun 2010; the update SimOpt uses, Chebotar et al. 2019) looks for
the distribution p over N samples theta_i ~ N(mu, Sigma) that minimises the expected cost subject to
KL(p || uniform) <= epsilon. Its solution is p_i ∝ exp(-c_i / eta), with the temperature eta > 0 the
minimiser of the dual

    g(eta) = eta * epsilon + eta * log( (1/N) sum_i exp(-c_i / eta) ),

which is convex with g'(eta) = epsilon - KL(p_eta || uniform). KL(p_eta || uniform) falls
monotonically from log(N / #best) at eta -> 0 to 0 at eta -> inf, so eta* is the root of
KL(p_eta || uniform) = epsilon, found by bisection in log(eta). A minimum temperature (in units of the
costs' standard deviation, so it does not depend on the costs' scale) keeps the weights from putting
everything on one sample; when it binds the weights' KL is below epsilon.

The bound above holds for the weights on the samples, not for the Gaussian fitted to them: the weighted
maximum-likelihood fit of a few effective samples can be much narrower, or further away, than epsilon
allows. So the step is also bounded in the Gaussian KL(new || old): the fitted Gaussian (its covariance
floored at the minimum) is interpolated with the old one, mean and covariance moving by the same
fraction alpha in [0, 1], and alpha is the largest that keeps KL(new || old) <= epsilon (bisection;
alpha = 1 when the fit already satisfies it). The interpolated covariance is a convex combination of two
matrices above the floor, so it stays above the floor too.
"""

from __future__ import annotations

import dataclasses
import math

import torch

# bisection steps: log-temperature and step fraction to far below any tolerance that matters here
_BISECTION_STEPS = 100


@dataclasses.dataclass(frozen=True)
class Gaussian:
    """N(mean, cov) over the parameters, float64."""

    mean: torch.Tensor
    cov: torch.Tensor

    def __post_init__(self) -> None:
        mean, cov = self.mean.double(), self.cov.double()
        d = mean.shape[-1]
        if mean.ndim != 1 or cov.shape != (d, d):
            raise ValueError(f"Gaussian needs mean [D] and cov [D, D], got {tuple(mean.shape)} and {tuple(cov.shape)}")
        if not (torch.isfinite(mean).all() and torch.isfinite(cov).all()):
            raise ValueError("Gaussian mean and covariance must be finite")
        cov = 0.5 * (cov + cov.T)
        if torch.linalg.cholesky_ex(cov).info != 0:
            raise ValueError("Gaussian covariance must be positive definite")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @property
    def dim(self) -> int:
        return self.mean.shape[0]

    def sample(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        eps = torch.randn(n, self.dim, dtype=torch.float64, generator=generator)
        return self.mean + eps @ torch.linalg.cholesky(self.cov).T

    def kl(self, other: Gaussian) -> float:
        """KL(self || other), exact."""
        L = torch.linalg.cholesky(other.cov)
        a = torch.linalg.solve_triangular(L, self.cov, upper=False)
        trace = torch.trace(torch.linalg.solve_triangular(L.T, a, upper=True))
        z = torch.linalg.solve_triangular(L, (other.mean - self.mean)[:, None], upper=False)
        logdet_other = 2 * torch.log(torch.diagonal(L)).sum()
        logdet_self = torch.linalg.slogdet(self.cov)[1]
        return float(0.5 * (trace + (z**2).sum() - self.dim + logdet_other - logdet_self))


@dataclasses.dataclass(frozen=True)
class RepsWeights:
    weights: torch.Tensor  # [N], sum to 1
    temperature: float  # eta, in the costs' units (inf: all costs equal, uniform weights)
    kl: float  # KL(weights || uniform) <= epsilon


def weights_at(costs: torch.Tensor, temperature: float) -> tuple[torch.Tensor, float]:
    """p_i ∝ exp(-c_i / eta) and KL(p || uniform)."""
    log_p = torch.log_softmax(-(costs.double() - costs.min()) / temperature, 0)
    return log_p.exp(), float((log_p.exp() * (log_p + math.log(len(costs)))).sum())


def reps_weights(costs: torch.Tensor, epsilon: float, min_temperature: float) -> RepsWeights:
    """Sample weights and temperature minimising the dual, with eta >= min_temperature * std(costs)."""
    c = costs.double()
    if c.ndim != 1 or len(c) < 2:
        raise ValueError(f"REPS needs a vector of at least 2 costs, got shape {tuple(c.shape)}")
    if not torch.isfinite(c).all():
        raise ValueError("REPS costs must be finite (drop diverged samples first)")
    if not epsilon > 0 or not min_temperature > 0:
        raise ValueError(f"need epsilon > 0 and min_temperature > 0, got {epsilon} and {min_temperature}")
    spread = float(c.std())
    if spread == 0.0:
        return RepsWeights(torch.full_like(c, 1.0 / len(c)), math.inf, 0.0)
    low = min_temperature * spread
    w, kl = weights_at(c, low)
    if kl <= epsilon:  # the minimum temperature binds (or epsilon exceeds the largest reachable KL)
        return RepsWeights(w, low, kl)
    high = spread
    while weights_at(c, high)[1] > epsilon:
        high *= 2.0
    log_lo, log_hi = math.log(low), math.log(high)
    for _ in range(_BISECTION_STEPS):  # invariant: KL(lo) > epsilon >= KL(hi)
        mid = 0.5 * (log_lo + log_hi)
        if weights_at(c, math.exp(mid))[1] > epsilon:
            log_lo = mid
        else:
            log_hi = mid
    temperature = math.exp(log_hi)
    w, kl = weights_at(c, temperature)
    return RepsWeights(w, temperature, kl)


def weighted_fit(theta: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted maximum-likelihood mean and covariance of samples theta [N, D]."""
    theta, w = theta.double(), weights.double()
    mean = w @ theta
    d = theta - mean
    return mean, (w[:, None] * d).T @ d


def floor_covariance(cov: torch.Tensor, min_std: torch.Tensor) -> torch.Tensor:
    """The nearest covariance with cov >= diag(min_std^2) in the Loewner order (eigenvalues clamped
    in the coordinates where the floor is the identity): no direction collapses below the floor."""
    scale = min_std.double()
    whitened = cov.double() / scale[:, None] / scale[None, :]
    values, vectors = torch.linalg.eigh(0.5 * (whitened + whitened.T))
    clamped = (vectors * values.clamp_min(1.0)) @ vectors.T
    return clamped * scale[:, None] * scale[None, :]


@dataclasses.dataclass(frozen=True)
class RepsStep:
    gaussian: Gaussian
    temperature: float
    weights_kl: float  # KL(weights || uniform), bounded by epsilon
    gaussian_kl: float  # KL(new || old), bounded by epsilon
    step_fraction: float  # alpha: 1 unless the fitted Gaussian had to be pulled back to the bound
    effective_samples: float  # 1 / sum w_i^2


def reps_update(old: Gaussian, theta: torch.Tensor, costs: torch.Tensor, epsilon: float, min_temperature: float,
                min_std: torch.Tensor) -> RepsStep:
    """One REPS update of N(mu, Sigma) from samples theta [N, D] drawn from `old` and their costs [N]."""
    if theta.ndim != 2 or theta.shape != (len(costs), old.dim):
        raise ValueError(f"theta must be [{len(costs)}, {old.dim}] to match the costs, got {tuple(theta.shape)}")
    rw = reps_weights(costs, epsilon, min_temperature)
    mean, cov = weighted_fit(theta, rw.weights)
    fitted = Gaussian(mean, floor_covariance(cov, min_std))
    alpha, new = 1.0, fitted
    if fitted.kl(old) > epsilon:
        lo, hi = 0.0, 1.0  # invariant: KL(lo) <= epsilon < KL(hi); KL(0) = 0
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if _between(old, fitted, mid).kl(old) <= epsilon:
                lo = mid
            else:
                hi = mid
        alpha, new = lo, _between(old, fitted, lo)
    return RepsStep(new, rw.temperature, rw.kl, new.kl(old), alpha, float(1.0 / (rw.weights**2).sum()))


def _between(old: Gaussian, new: Gaussian, alpha: float) -> Gaussian:
    return Gaussian(old.mean + alpha * (new.mean - old.mean), (1 - alpha) * old.cov + alpha * new.cov)

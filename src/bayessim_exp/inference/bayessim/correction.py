"""The posterior given one or several real summaries, with the SNPE-A proposal correction.

A model trained on simulations with theta ~ p~(theta) estimates q(theta | x) proportional to
p~(theta) p(x | theta). With real summaries x_1..x_n that are independent given theta, and
q_i trained under proposal p~_i,

    p(theta | x_1..n)  proportional to  p(theta) * prod_i q_i(theta | x_i) / p~_i(theta).

(With p~_i = p this is the product of per-trajectory posteriors divided by p^(n-1).)
For Gaussian-mixture q_i and Gaussian or box-uniform p and p~_i the right-hand side is a
Gaussian mixture (truncated to the prior's box) in closed form: the product of the q_i is a
mixture (pruned to `max_components` after every factor), and the Gaussian ratio
N(mu0, S0) / prod N(mu_i, S_i) adds Lambda = S0^-1 - sum S_i^-1 to every component's precision.
When a component's precision is not positive definite, or a factor is not Gaussian (flows,
log-uniform priors, mixture proposals), the same unnormalised density is used exactly through
importance sampling (distributions/importance.py), and a warning says so.
See docs/statistics.md for the assumptions.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable, Sequence

import torch

from ...data_files import data_class
from ...distributions.base import NOT_GAUSSIAN, ParameterDistribution
from ...distributions.importance import DefensiveMixture, ImportancePosterior
from ...distributions.mixture import GaussianMixture, NotPositiveDefinite, TruncatedMixture
from ...distributions.mixture_stack import MixtureStack
from ...distributions.restricted import Restricted
from ...stages import info_once_per_round

log = logging.getLogger(__name__)

# importance fallback: base draws (method.importance_draws), and covariance inflation of the base's defensive half
IMPORTANCE_DRAWS = 100_000
_INFLATE = 4.0
_MOMENT_DRAWS = 4000
# mixture components kept in products: the Python API's default (the pipeline's is method.max_components)
MAX_COMPONENTS = 50


def _gaussian_factor(dist) -> tuple[torch.Tensor, torch.Tensor] | None | str:
    """(mean, cov) if dist is Gaussian on its support, None if constant there (None: an improper flat prior),
    NOT_GAUSSIAN if neither (ParameterDistribution.gaussian_factor; any other distribution is neither)."""
    if dist is None:
        return None
    return dist.gaussian_factor() if isinstance(dist, ParameterDistribution) else NOT_GAUSSIAN


def _as_mixture(dist) -> GaussianMixture | None:
    """dist where it is a Gaussian mixture over R^D; None for the rest (flows, torch distributions)."""
    return dist.as_gaussian_mixture() if isinstance(dist, ParameterDistribution) else None


def _box(dist) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The support box of a distribution; None for an improper flat prior or an unbounded one."""
    if dist is None or dist.low is None:
        return None
    return dist.low.double(), dist.high.double()


def needs_no_correction(proposal, prior) -> bool:
    """The prior itself, or the prior truncated to a high-density region (constant ratio there)."""
    return proposal is None or proposal is prior or (isinstance(proposal, ParameterDistribution)
                                                     and proposal.restricts(prior))


def _check_covers(prior, proposal) -> None:
    """SNPE-A needs p~ > 0 wherever p > 0: a proposal box must contain the prior's."""
    pb, qb = _box(prior), _box(proposal)
    if qb is not None and (pb is None or (qb[0] > pb[0]).any() or (qb[1] < pb[1]).any()):
        raise ValueError("the proposal's support must contain the prior's for the SNPE-A correction")


def _natural(mean: torch.Tensor, cov: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    prec = torch.cholesky_inverse(torch.linalg.cholesky(cov.double()))
    return prec, prec @ mean.double()


def _apply_gaussian_ratio(mix: GaussianMixture, lam: torch.Tensor, eta: torch.Tensor) -> GaussianMixture | None:
    """mix(theta) * exp(-theta^T lam theta / 2 + eta^T theta), renormalised; None if a precision is not PD."""
    logdet_s = 2 * torch.log(torch.diagonal(mix.scale_tril, dim1=-2, dim2=-1)).sum(-1)
    logits, means, covs, ok = _gaussian_ratio(mix.log_weights, mix.means, torch.cholesky_inverse(mix.scale_tril),
                                              logdet_s, lam, eta)
    return GaussianMixture(logits, means, covs) if bool(ok) else None


def _gaussian_ratio(log_weights: torch.Tensor, means: torch.Tensor, s_inv: torch.Tensor, logdet_s: torch.Tensor,
                    lam: torch.Tensor, eta: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """(logits, means, covs, ok) of `_apply_gaussian_ratio` from a mixture's log weights [..., K], means, inverse
    covariances S_k^-1 and their log determinants, of one mixture or a stack of them; ok [...]: whether every
    component's precision is positive definite (the mixture's other entries mean nothing where not).

    Component k gets precision P_k = S_k^-1 + lam and weight w_k * integral of the product:
    log c_k = -1/2 log|S_k| - 1/2 log|P_k| - 1/2 m_k^T S_k^-1 m_k + 1/2 e_k^T P_k^-1 e_k, e_k = S_k^-1 m_k + eta.
    """
    lam, eta = lam.to(means.device), eta.to(means.device)
    prec = s_inv + lam
    chol, info = torch.linalg.cholesky_ex(0.5 * (prec + prec.transpose(-1, -2)))
    s_inv_m = (s_inv @ means.unsqueeze(-1)).squeeze(-1)
    e = s_inv_m + eta
    new_means = torch.cholesky_solve(e.unsqueeze(-1), chol).squeeze(-1)
    logdet_p = 2 * torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    log_c = -0.5 * logdet_s - 0.5 * logdet_p - 0.5 * (means * s_inv_m).sum(-1) + 0.5 * (e * new_means).sum(-1)
    return log_weights + log_c, new_means, torch.cholesky_inverse(chol), (info == 0).all(-1)


def _stack_closed_form(stack: MixtureStack, tau: float, lam, eta) -> tuple[torch.Tensor, ...]:
    """(logits, means, covs, ok) of `_closed_form` for every product of a stack. The tempered components'
    precisions are tau times the product's, computed once for every temperature, not refactorised at each
    (the same to rounding)."""
    logits = tau * stack.log_weights + 0.5 * (1 - tau) * stack.log_dets
    if lam is None:
        return logits, stack.means, stack.covs / tau, torch.ones(len(stack), dtype=torch.bool)
    return _gaussian_ratio(torch.log_softmax(logits, -1), stack.means, tau * stack.precisions,
                           stack.log_dets - stack.dim * math.log(tau), lam, eta)


def moments(dist, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and covariance: exact for a Gaussian mixture, else from _MOMENT_DRAWS seeded draws."""
    mixture = _as_mixture(dist)
    if mixture is not None:
        return mixture.mean, mixture.covariance
    s = dist.sample((_MOMENT_DRAWS,), generator=torch.Generator().manual_seed(seed)).double()
    return s.mean(0), torch.atleast_2d(torch.cov(s.T))


def _moment_gaussian(dist) -> GaussianMixture:
    mixture = _as_mixture(dist)
    if mixture is not None:
        return mixture
    mean, cov = moments(dist)
    return GaussianMixture(torch.zeros(1), mean[None], cov[None])


def _product(mixtures: Sequence[GaussianMixture], max_components: int) -> GaussianMixture:
    out = mixtures[0].prune(max_components)
    for m in mixtures[1:]:
        out = out.product(m, max_components)
    return out


def _side_by_side(mixtures: Sequence[GaussianMixture]) -> GaussianMixture:
    """One mixture of all the components, each mixture's weights scaled by 1 / len(mixtures)."""
    log_weights = torch.cat([torch.log_softmax(m.log_weights.double(), -1) for m in mixtures]) - math.log(len(mixtures))
    return GaussianMixture(log_weights, torch.cat([m.means.double() for m in mixtures]),
                           torch.cat([m.covs.double() for m in mixtures]))


def _temper(mix: GaussianMixture, tau: float) -> GaussianMixture:
    """mix^tau renormalised, component by component: N(m, S)^tau is proportional to N(m, S / tau) with
    integral proportional to |S|^((1 - tau) / 2). Exact for one component or well-separated ones."""
    if tau == 1.0:
        return mix
    logdet = 2 * torch.log(torch.diagonal(mix.scale_tril, dim1=-2, dim2=-1)).sum(-1)
    return GaussianMixture(tau * mix.log_weights + 0.5 * (1 - tau) * logdet, mix.means, mix.covs / tau)


def posterior(conditionals: Sequence, prior, proposal=None, *, max_components: int = MAX_COMPONENTS, seed: int = 0,
              temperature: float = 1.0, importance_draws: int = IMPORTANCE_DRAWS):
    """p(theta | x_1..n) from q(theta | x_i) for each real summary (see the module docstring).

    conditionals: one q(theta | x_i) per real summary, GaussianMixtures (closed form) or any
        distribution with sample/log_prob (flows).
    prior: the prior p; its box (`low`/`high`), when it has one, is the posterior's support; None is
        an improper flat prior.
    proposal: p~, the distribution the training simulations were drawn from; None, the prior itself
        or a TruncatedPrior of it mean no correction; a list gives one proposal per conditional.
    temperature: tau in (0, 1], the power of the likelihood ratios prod_i q_i / p~_i (1: the plain
        product; combination.py chooses it when trajectories disagree).
    importance_draws: the base draws of the importance-sampled posterior where there is no closed form.
    Returns a distribution with sample(shape) and log_prob(theta).
    """
    return tempered_posterior(conditionals, prior, proposal, max_components=max_components, seed=seed,
                              importance_draws=importance_draws)(temperature)


def tempered_posterior(conditionals: Sequence, prior, proposal=None, *, max_components: int = MAX_COMPONENTS,
                       seed: int = 0, importance_draws: int = IMPORTANCE_DRAWS,
                       warn: bool = True) -> Callable[[float], ParameterDistribution]:
    """`posterior` as a function of the temperature, for callers that need it at several: the product of the
    conditionals, which no temperature changes (the power is applied to it), is computed once, at the first
    call that needs it. warn=False logs an importance-sampled result at debug level (simulated sets: a
    thousand of them a round)."""
    n = len(conditionals)
    corrected = _corrected(n, prior, proposal)
    box = _box(prior)
    prior_factor = _gaussian_factor(prior)

    @functools.cache
    def product(narrowed: bool) -> GaussianMixture | None:
        return _set_product(conditionals, prior_factor, narrowed, max_components)

    @functools.cache
    def moment_product() -> GaussianMixture:
        # the importance sampler's proposal; where no product factorises, the conditionals side by side still
        # cover where each puts its mass
        gaussians = [_moment_gaussian(q) for q in conditionals]
        try:
            return _product(gaussians, max_components)
        except NotPositiveDefinite:
            return _side_by_side(gaussians)

    def at(temperature: float):
        tau = _checked(temperature)
        prior_power = 1 - tau * (n - len(corrected))  # p * prod over uncorrected factors of (1/p)^tau
        reason = _closed_form_obstacle(conditionals, prior, prior_power, corrected)
        if reason is None:
            lam, eta = _ratio_natural(prior, prior_power, corrected, conditionals[0].dim, tau)
            result = _closed_form(product(False), tau, lam, eta)
            if result is None and isinstance(prior_factor, tuple):
                result = _closed_form(product(True), tau, lam, eta)
                if result is not None:
                    info_once_per_round(log, _NARROWED)
            if result is not None:
                return result if box is None else TruncatedMixture(result, *box, seed=seed)
            reason = "the product or a component's corrected precision is not positive definite"
        elif n == 1 and prior_power == 0 and not corrected:
            q = conditionals[0]  # a flow trained on prior draws: its density is the posterior up to the support
            return q if box is None else Restricted(q, *box, seed=seed)
        base_mix = _temper(moment_product(), tau)
        inflated = GaussianMixture(base_mix.log_weights, base_mix.means, _INFLATE * base_mix.covs)
        parts = [base_mix, inflated] + ([conditionals[0]] if n == 1 else [])
        if box is not None:  # the conditionals' Gaussians may put their mass outside the box the target lives in
            parts.append(prior)
        log_target = CorrectedProduct(list(conditionals), prior, prior_power, corrected, tau)
        result = ImportancePosterior(log_target, DefensiveMixture(parts), num=importance_draws, seed=seed)
        log.log(logging.WARNING if warn else logging.DEBUG, "posterior: no closed form (%s); using importance "
                "sampling with %d draws, effective sample size %.0f", reason, importance_draws, result.ess)
        return result

    return at


def tempered_posteriors(sets: Sequence[Sequence], prior, proposal=None, *, max_components: int = MAX_COMPONENTS,
                        seed: int = 0, importance_draws: int = IMPORTANCE_DRAWS, device: torch.device | str = "cpu"
                        ) -> Callable[[float], MixtureStack | list[ParameterDistribution]]:
    """`tempered_posterior` (warn=False) of each of many sets of as many conditionals (the simulated sets that
    set_calibration.py fits the temperature on), as a function of the temperature. Where every set's posterior is
    a Gaussian mixture over R^D in closed form (no box to truncate it to: probit space), their MixtureStack on
    `device`, tempered and corrected for all sets at once by the same formulas; at a temperature where one is not,
    the list of each set's posterior."""
    singles = [tempered_posterior(c, prior, proposal, max_components=max_components, seed=seed,
                                  importance_draws=importance_draws, warn=False) for c in sets]
    n = len(sets[0])
    corrected = _corrected(n, prior, proposal)
    prior_factor = _gaussian_factor(prior)
    mixtures = _box(prior) is None and all(_as_mixture(q) is not None for c in sets for q in c)

    @functools.cache
    def product(i: int, narrowed: bool) -> GaussianMixture | None:
        return _set_product(sets[i], prior_factor, narrowed, max_components)

    @functools.cache
    def stack_of(which: tuple[int, ...], narrowed: bool) -> MixtureStack | None:
        stack = MixtureStack.of([product(i, narrowed) for i in which])
        return None if stack is None else stack.to(device)

    def stacked(tau: float) -> MixtureStack | None:
        """`tempered_posterior`'s closed form for every set, from the narrowed product where the plain one has
        none; None where a set has neither (or the products' sizes differ)."""
        prior_power = 1 - tau * (n - len(corrected))
        if not mixtures or _closed_form_obstacle(sets[0], prior, prior_power, corrected) is not None:
            return None
        lam, eta = _ratio_natural(prior, prior_power, corrected, sets[0][0].dim, tau)
        parts, todo = None, list(range(len(sets)))
        for narrowed in (False, True) if isinstance(prior_factor, tuple) else (False,):
            which = [i for i in todo if product(i, narrowed) is not None]
            stack = stack_of(tuple(which), narrowed) if which else None
            if stack is None:
                if which:
                    return None
                continue
            logits, means, covs, ok = _stack_closed_form(stack, tau, lam, eta)
            ok = ok.cpu()
            if len(which) == len(sets) and ok.all():
                return MixtureStack(logits, means, covs)
            if parts is None:
                parts = [t.new_zeros(len(sets), *t.shape[1:]) for t in (logits, means, covs)]
            if parts[2].shape[1:] != covs.shape[1:]:
                return None
            rows = torch.tensor(which, dtype=torch.long)[ok]
            for part, values in zip(parts, (logits, means, covs)):
                part[rows.to(part.device)] = values[ok.to(values.device)]
            placed = set(rows.tolist())
            todo = [i for i in todo if i not in placed]
            if narrowed and len(rows):
                info_once_per_round(log, _NARROWED)
        return None if todo else MixtureStack(*parts)

    def at(temperature: float) -> MixtureStack | list[ParameterDistribution]:
        tau = _checked(temperature)
        stack = stacked(tau)
        return [single(tau) for single in singles] if stack is None else stack

    return at


_NARROWED = "posterior: components wider than the prior narrowed to it, keeping the closed form"


def _checked(temperature: float) -> float:
    if not 0.0 < temperature <= 1.0:
        raise ValueError(f"temperature must be in (0, 1], got {temperature}")
    return float(temperature)


def _corrected(n: int, prior, proposal) -> list:
    """The proposals, one per conditional, that the product divides by (those that are not the prior or a
    restriction of it), checked to cover the prior."""
    if n == 0:
        raise ValueError("posterior needs at least one real summary")
    proposals = list(proposal) if isinstance(proposal, (list, tuple)) else [proposal] * n
    if len(proposals) != n:
        raise ValueError(f"{len(proposals)} proposals for {n} real summaries")
    corrected = [p for p in proposals if not needs_no_correction(p, prior)]
    for p in corrected:
        _check_covers(prior, p)
    return corrected


def _set_product(conditionals: Sequence, prior_factor, narrowed: bool, max_components: int) -> GaussianMixture | None:
    """The conditionals' product; None where double precision cannot factorise it.

    A component wider than a Gaussian prior is a fitting artefact (no posterior of a Gaussian prior is); dividing
    by the prior then leaves a negative precision, and far wider ones (a model far outside its training summaries:
    variances of 1e14) leave products double precision cannot factorise: `narrowed` clamps them to the prior's."""
    try:
        factors = [_no_wider_than(q, prior_factor[1]) for q in conditionals] if narrowed else conditionals
        return _product(factors, max_components)
    except NotPositiveDefinite:
        return None


def _closed_form(product: GaussianMixture | None, tau: float, lam, eta) -> GaussianMixture | None:
    """The conditionals' product raised to tau, times exp(-theta^T lam theta / 2 + eta^T theta); None where the
    product or a corrected precision is not positive definite."""
    if product is None:
        return None
    mix = _temper(product, tau)
    return mix if lam is None else _apply_gaussian_ratio(mix, lam, eta)


def loewner_min(covs: torch.Tensor, cov0: torch.Tensor) -> torch.Tensor:
    """Covariances [..., D, D] with their eigenvalues relative to cov0 (those of L0^-1 S L0^-T, cov0 =
    L0 L0^T) clamped at 1: no wider than cov0 in any direction, unchanged where they are narrower."""
    chol0 = torch.linalg.cholesky(cov0.double())
    white = torch.linalg.solve_triangular(chol0, torch.linalg.solve_triangular(chol0, covs.double(), upper=False)
                                          .transpose(-1, -2), upper=False)
    values, vectors = torch.linalg.eigh(0.5 * (white + white.transpose(-1, -2)))
    clamped = vectors @ torch.diag_embed(values.clamp(max=1.0)) @ vectors.transpose(-1, -2)
    return chol0 @ clamped @ chol0.T


def _no_wider_than(mix: GaussianMixture, cov0: torch.Tensor) -> GaussianMixture:
    return GaussianMixture(mix.log_weights, mix.means, loewner_min(mix.covs, cov0))


@data_class
class CorrectedProduct:
    """log p(theta)^prior_power + tau * (sum_i log q_i(theta | x_i) - sum_j log p~_j(theta)), up to a
    constant; -inf outside the prior's support. A class, not a closure, so posteriors built on it can be saved."""

    def __init__(self, conditionals: list, prior, prior_power: float, corrected: list, tau: float):
        self.conditionals, self.prior, self.prior_power = conditionals, prior, prior_power
        self.corrected, self.tau = corrected, tau

    def __call__(self, theta: torch.Tensor) -> torch.Tensor:
        theta = theta.double()
        lp = torch.zeros(theta.shape[:-1], dtype=torch.float64) if self.prior is None else self.prior.log_prob(theta).double()
        out = self.tau * sum(q.log_prob(theta).double() for q in self.conditionals)
        if self.prior_power:
            out = out + self.prior_power * lp
        for p in self.corrected:
            out = out - self.tau * p.log_prob(theta).double()
        return torch.where(torch.isfinite(lp), out, torch.tensor(-torch.inf, dtype=out.dtype))


def _closed_form_obstacle(conditionals, prior, prior_power: float, corrected: list) -> str | None:
    if any(_as_mixture(q) is None for q in conditionals):
        return "the conditional density is not a Gaussian mixture"
    if prior_power != 0 and _gaussian_factor(prior) is NOT_GAUSSIAN:
        return f"the prior ({type(prior).__name__}) is neither Gaussian nor uniform"
    for p in corrected:
        if _gaussian_factor(p) is NOT_GAUSSIAN:
            return f"the proposal ({type(p).__name__}) is not a single Gaussian or uniform"
    return None


def _ratio_natural(prior, prior_power: float, corrected: list, dim: int, tau: float):
    """Natural parameters (lam, eta) of p^prior_power / prod p~_i^tau, or (None, None) if constant."""
    lam = torch.zeros(dim, dim, dtype=torch.float64)
    eta = torch.zeros(dim, dtype=torch.float64)
    constant = True
    factors = [(prior_power, _gaussian_factor(prior))] + [(-tau, _gaussian_factor(p)) for p in corrected]
    for power, factor in factors:
        if power != 0 and factor is not None:
            prec, shift = _natural(*factor)
            lam, eta, constant = lam + power * prec, eta + power * shift, False
    return (None, None) if constant else (lam, eta)

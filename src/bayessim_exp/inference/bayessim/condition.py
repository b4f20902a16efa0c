"""BayesSim conditioning: the posterior given every real trajectory collected so far.

For i.i.d. real summaries x_1..x_n and a model trained on simulations from `proposal`,
p(theta | x_1..x_n) is proportional to p(theta) * prod_i q(theta | x_i) / proposal(theta)
(SNPE-A; the product of per-trajectory posteriors over p^(n-1) when the proposal is the prior).
correction.py computes it, in closed form where it exists; docs/statistics.md explains.
A model fitted in probit space (distributions/probit.py) is conditioned there, under the standard
normal prior, and the result is mapped back to the box.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from ...distributions.base import ParameterDistribution
from ...distributions.mixture_stack import MixtureStack
from ...distributions.probit import ProbitPosterior, ProbitTransform, standard_normal_prior
from ...models.base import PosteriorModel
from .combination import Dispersion, combine
from .correction import IMPORTANCE_DRAWS, MAX_COMPONENTS, needs_no_correction, tempered_posterior, tempered_posteriors


def condition(model: PosteriorModel, x_obs: torch.Tensor, prior, max_components: int = MAX_COMPONENTS, proposal=None,
              seed: int = 0, probit: ProbitTransform | None = None, combination: str = "dispersion",
              temperature: float = 1.0,
              importance_draws: int = IMPORTANCE_DRAWS) -> tuple[ParameterDistribution, Dispersion | None]:
    """The posterior given x_obs [n, F] (or one summary [F]), and the dispersion of the per-trajectory
    posteriors (None for one summary); `combination` says how several summaries are combined
    (combination.py), `temperature` widens it further (combine).

    prior None means an improper flat prior (no truncation); proposal None means simulations from the prior.
    probit: the transform the model's parameters were fitted in, or None for parameter units.
    importance_draws: the base draws of a posterior without a closed form (correction.py).
    """
    conditionals = [model.conditional(x) for x in x_obs.reshape(-1, x_obs.shape[-1])]
    if probit is None:
        return combine(combination, conditionals, prior, proposal, max_components=max_components, seed=seed,
                       temperature=temperature, importance_draws=importance_draws)
    post, spread = combine(combination, conditionals, standard_normal_prior(probit.dim),
                           _probit_proposal(proposal, prior), max_components=max_components, seed=seed,
                           temperature=temperature, importance_draws=importance_draws)
    return ProbitPosterior(post, probit), spread


def tempered_product(conditionals: list, prior, max_components: int = MAX_COMPONENTS, proposal=None, seed: int = 0,
                     probit: ProbitTransform | None = None,
                     importance_draws: int = IMPORTANCE_DRAWS,
                     warn: bool = True) -> Callable[[float], ParameterDistribution]:
    """The posterior given the model's per-trajectory posteriors q(theta | x_i), combined as their product with
    the likelihood ratios raised to a temperature, as a function of the temperature (correction.py's
    tempered_posterior: the product is computed once however many temperatures are asked for; `warn` as there)."""
    if probit is None:
        return tempered_posterior(conditionals, prior, proposal, max_components=max_components, seed=seed,
                                  importance_draws=importance_draws, warn=warn)
    at = tempered_posterior(conditionals, standard_normal_prior(probit.dim), _probit_proposal(proposal, prior),
                            max_components=max_components, seed=seed, importance_draws=importance_draws, warn=warn)
    return lambda temperature: ProbitPosterior(at(temperature), probit)


def tempered_products(sets: list[list], prior, max_components: int = MAX_COMPONENTS, proposal=None, seed: int = 0,
                      probit: ProbitTransform | None = None, importance_draws: int = IMPORTANCE_DRAWS,
                      device: torch.device | str = "cpu"
                      ) -> Callable[[float], MixtureStack | list[ParameterDistribution]]:
    """`tempered_product` (warn=False) of each of many sets of per-trajectory posteriors, as a function of the
    temperature: correction.py's tempered_posteriors, their MixtureStack (on `device`) where every set's is in closed
    form, else the list of each set's posterior."""
    if probit is None:
        return tempered_posteriors(sets, prior, proposal, max_components=max_components, seed=seed,
                                   importance_draws=importance_draws, device=device)
    at = tempered_posteriors(sets, standard_normal_prior(probit.dim), _probit_proposal(proposal, prior),
                             max_components=max_components, seed=seed, importance_draws=importance_draws, device=device)

    def mapped(temperature: float) -> MixtureStack | list[ParameterDistribution]:
        posteriors = at(temperature)
        if isinstance(posteriors, MixtureStack):
            return posteriors.mapped(probit)
        return [ProbitPosterior(p, probit) for p in posteriors]

    return mapped


def _probit_proposal(proposal, prior):
    """The proposal's density over u: none to correct for the prior or a truncation of it (constant
    ratio); a previous probit-space posterior's inner distribution."""
    if needs_no_correction(proposal, prior):
        return None
    inner = proposal.in_probit_space()
    if inner is not None:
        return inner
    raise ValueError(f"a probit-space model cannot correct for a {type(proposal).__name__} proposal in parameter units; "
                     "use proposal=truncated, prior or posterior")

"""Next-round proposals (docs/statistics.md): what rounds after the first draw their parameters from, built from
the distribution the previous round handed on. One class per `method.proposal` option:

    prior      always the prior; every round's simulations train the model
    posterior  the previous posterior itself (SNPE-A; closed form only for one-component mixtures)
    gaussian   the previous posterior moment-matched to one Gaussian (SNPE-A in closed form for mixtures)
    truncated  the prior restricted to the previous posterior's 99.9 % HPD region (TSNPE, no correction)

A researcher adds one with `@register_proposal` in a module named in the top-level `plugins` list.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import ClassVar

import torch

from ...distributions.base import ParameterDistribution
from ...distributions.mixture import GaussianMixture, TruncatedMixture
from ...distributions.probit import ProbitPosterior, ProbitTransform
from ...distributions.truncated_prior import TruncatedPrior
from ...errors import ConfigError

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class ProposalInputs:
    """What a round's proposal is built from besides the distribution the previous round handed on."""

    round: int
    prior: ParameterDistribution
    probit: ProbitTransform | None  # the transform the model is fitted in; None: parameter units
    seed: int  # the proposal stage's: stage_seed(run seed, round, "proposal")


class Proposal:
    """How rounds after the first draw their parameters: `build` answers round r's distribution, or None for the
    prior (recorded as 'prior' in results.json), from what round r - 1 handed on. The method's proposal stage
    saves the distribution, so it must be made of data classes (data_files.py), as every posterior is."""

    name: ClassVar[str]  # method.proposal's value, recorded in results.json
    # whether a round's model trains on every round's simulations; SNPE-A's correction divides by one
    # proposal, so the model must then be trained on the current round's draws only
    pools_rounds: ClassVar[bool] = True

    def build(self, previous: ParameterDistribution, inputs: ProposalInputs) -> ParameterDistribution | None:
        """previous: the prior where the guard fell back to it (every proposal then simulates from the prior)."""
        return None if previous is inputs.prior else self.from_posterior(previous, inputs)

    def from_posterior(self, posterior: ParameterDistribution, inputs: ProposalInputs) -> ParameterDistribution | None:
        raise NotImplementedError


PROPOSALS: dict[str, type[Proposal]] = {}


def register_proposal(cls: type[Proposal]) -> type[Proposal]:
    """Class decorator: make `cls` the option `method.proposal=<cls.name>`."""
    PROPOSALS[cls.name] = cls
    return cls


def proposal_named(name: str) -> Proposal:
    if name not in PROPOSALS:
        raise ConfigError(f"proposal={name!r} not allowed; allowed: {', '.join(PROPOSALS)}")
    return PROPOSALS[name]()


@register_proposal
class PriorProposal(Proposal):
    name = "prior"

    def build(self, previous: ParameterDistribution, inputs: ProposalInputs) -> None:
        return None


@register_proposal
class PosteriorProposal(Proposal):
    name = "posterior"
    pools_rounds = False

    def from_posterior(self, posterior: ParameterDistribution, inputs: ProposalInputs) -> ParameterDistribution:
        return posterior


@register_proposal
class GaussianProposal(Proposal):
    """Moment-matched in probit space where the model is fitted there (a Gaussian over u is a proposal the
    correction divides by in closed form), else in parameter units, truncated to the prior's box."""

    name = "gaussian"
    pools_rounds = False

    def from_posterior(self, posterior: ParameterDistribution, inputs: ProposalInputs) -> ParameterDistribution:
        if inputs.probit is not None:
            return ProbitPosterior(moment_matched(posterior.in_probit_space(), seed=inputs.seed), inputs.probit)
        return moment_matched(posterior, inputs.prior.low, inputs.prior.high, seed=inputs.seed)


@register_proposal
class TruncatedProposal(Proposal):
    """Where the posterior has no mixture form and its region is too small a share of the prior to sample (many
    parameters: the candidates are the whole prior, truncated_prior.py), the region of the Gaussian with its
    moments, in probit space where the model is fitted there (sampled in any number of parameters); the prior only
    where that fails too."""

    name = "truncated"

    def from_posterior(self, posterior: ParameterDistribution, inputs: ProposalInputs) -> ParameterDistribution | None:
        try:
            return TruncatedPrior(inputs.prior, posterior, seed=inputs.seed)
        except ValueError as exc:
            log.warning("round %d: %s; truncating to the region of the Gaussian with the posterior's moments instead",
                        inputs.round, exc)
        try:
            return TruncatedPrior(inputs.prior, GaussianProposal().from_posterior(posterior, inputs), seed=inputs.seed)
        except ValueError as exc:
            log.warning("round %d: %s; simulating from the prior instead", inputs.round, exc)
            return None


def moment_matched(posterior, low: torch.Tensor | None = None, high: torch.Tensor | None = None,
                   num: int = 20_000, seed: int = 0):
    """A single Gaussian with the posterior's mean and covariance, truncated to [low, high] when given
    (the prior's box: simulated parameters must stay in range).

    As the next round's proposal it keeps the SNPE-A correction of mixture models in closed form.
    """
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        draws = posterior.sample((num,)).double()
    cov = torch.cov(draws.T).reshape(draws.shape[1], draws.shape[1])
    cov = cov + 1e-9 * cov.diagonal().mean() * torch.eye(cov.shape[0], dtype=cov.dtype)
    gaussian = GaussianMixture(torch.zeros(1), draws.mean(0, keepdim=True), cov[None])
    return gaussian if low is None else TruncatedMixture(gaussian, low, high, seed=seed)

"""What a finished BayesSim round handed on, read from its artifacts and the prior alone (registry: posterior),
so that api.load_run builds no simulator, summarizer or model to read it: the distribution domain randomization
gets, and where the next round's proposal comes from. Its guard says both; they differ where a round whose real data
lie outside its simulations hands an earlier posterior on but lets the next round propose elsewhere (escape.py)."""

from __future__ import annotations

import dataclasses

from ...distributions.base import ParameterDistribution
from ...stages import RoundContext

_READS = {"linear": "linear read of its real data", "nearest": "simulations nearest its real data"}


@dataclasses.dataclass(frozen=True)
class ProposalSource:
    """What a round's proposal is built from: round `round`'s posterior (0: the prior), or with `read` (escape.py's
    linear | nearest) the Gaussian that round read off its real data, kept in its guard's artifact."""

    round: int = 0
    read: str | None = None

    def describe(self) -> str:
        if self.round == 0:
            return "the prior"
        return f"round {self.round}'s " + (_READS[self.read] if self.read else "posterior")


def handed_on_round(ctx: RoundContext, round_index: int) -> int:
    """The round whose posterior round `round_index` handed on (its guard says); 0: the prior (also before round 1)."""
    return 0 if round_index == 0 else ctx.output("guard", round_index)["handed_on"]


def proposal_source(ctx: RoundContext, round_index: int) -> ProposalSource:
    """What round `round_index + 1` proposes from (round `round_index`'s guard says; the prior for round 1)."""
    if round_index == 0:
        return ProposalSource()
    guard = ctx.output("guard", round_index)
    return ProposalSource(guard["proposes_from"], guard["proposes_read"])


def posterior_of(ctx: RoundContext, prior: ParameterDistribution, source: int) -> ParameterDistribution:
    """Round `source`'s conditioned posterior; the prior for 0."""
    return prior if source == 0 else ctx.output("condition", source)["posterior"]


def handed_on(ctx: RoundContext, prior: ParameterDistribution, round_index: int | None = None) -> ParameterDistribution:
    """What round `round_index` (ctx.round by default) handed on."""
    return posterior_of(ctx, prior, handed_on_round(ctx, ctx.round if round_index is None else round_index))

"""What a finished BayesSim round handed on, read from its artifacts and the prior alone (registry: posterior),
so that api.load_run builds no simulator, summarizer or model to read it."""

from __future__ import annotations

from ...distributions.base import ParameterDistribution
from ...stages import RoundContext


def handed_on_round(ctx: RoundContext, round_index: int) -> int:
    """The round whose posterior round `round_index` handed on (its guard says); 0: the prior (also before round 1)."""
    return 0 if round_index == 0 else ctx.output("guard", round_index)["handed_on"]


def handed_on(ctx: RoundContext, prior: ParameterDistribution, round_index: int | None = None) -> ParameterDistribution:
    """What round `round_index` (ctx.round by default) handed on."""
    source = handed_on_round(ctx, ctx.round if round_index is None else round_index)
    return prior if source == 0 else ctx.output("condition", source)["posterior"]

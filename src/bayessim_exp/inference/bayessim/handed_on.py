"""What a finished BayesSim round handed on, read from its artifacts and the prior alone (registry: posterior),
so that api.load_run builds no simulator, summarizer or model to read it."""

from __future__ import annotations

from ...distributions.base import ParameterDistribution
from ...stages import RoundContext


def handed_on(ctx: RoundContext, prior: ParameterDistribution) -> ParameterDistribution:
    """Round ctx.round's guard names the round whose posterior it handed on (0: the prior)."""
    source = ctx.output("guard")["handed_on"]
    return prior if source == 0 else ctx.output("condition", source)["posterior"]

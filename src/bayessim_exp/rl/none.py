"""rl=none: no RL stage; rounds only refine the posterior."""

from __future__ import annotations

import dataclasses

import torch

from ..stages import RoundContext, Stage


@dataclasses.dataclass
class NoRLConfig:
    pass


class NoRL:
    """The RL component of a run without RL: no stages, no actor, and no surrogate-real return to record."""

    def stages(self) -> list[Stage]:
        return []

    def actor(self, ctx: RoundContext) -> torch.nn.Module | None:
        return None

    def record(self, ctx: RoundContext) -> dict:
        return {"surrogate_real_return": None}  # results.json has the key with or without RL


def no_rl(cfg: NoRLConfig, **_: object) -> NoRL:
    return NoRL()

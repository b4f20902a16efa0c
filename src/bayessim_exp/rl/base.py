"""What the pipeline asks of an RL component (an option of the `rl` config group; rl=none builds one without
stages, rl/none.py)."""

from __future__ import annotations

from typing import Protocol

import torch

from ..stages import RoundContext, Stage


class RLComponent(Protocol):
    def stages(self) -> list[Stage]:
        """The round's RL stages, run after the inference method's."""
        ...

    def actor(self, ctx: RoundContext) -> torch.nn.Module | None:
        """The latest trained actor at this point of the round (None before the first), for policy=rl."""
        ...

    def record(self, ctx: RoundContext) -> dict:
        """This round's RL fields of results.json."""
        ...

"""What the pipeline asks of a summarizer (an option of the `summarizer` config group)."""

from __future__ import annotations

from typing import Protocol

import torch

from ..sim.trajectories import Trajectories


class Summarizer(Protocol):
    """Trajectories -> summaries [N, F]. A summarizer with a trainable `embedding` (nn.Module) hands it
    to the posterior model, which trains it jointly (summarizer=learned)."""

    def check(self, horizon: int) -> None:
        """Raise ConfigError if the summary cannot be taken from `horizon` steps."""
        ...

    def output_dim(self, state_dim: int, action_dim: int, horizon: int) -> int: ...

    def __call__(self, traj: Trajectories) -> torch.Tensor: ...

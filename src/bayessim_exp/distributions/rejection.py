"""Exact sampling from a distribution restricted to a region, by rejection."""

from __future__ import annotations

from collections.abc import Callable

import torch

_MAX_BATCH = 1 << 18  # candidates per round, so memory stays bounded when acceptance is low


def sample_by_rejection(draw: Callable[[int], torch.Tensor], keep: Callable[[torch.Tensor], torch.Tensor],
                        n: int, acceptance: float) -> torch.Tensor:
    """n draws [n, D] of draw(batch) that satisfy keep; batches sized from the known acceptance rate."""
    got, have = [], 0
    batch = min(max(256, int(1.2 * n / acceptance)), _MAX_BATCH)
    while have < n:
        candidates = draw(batch)
        candidates = candidates[keep(candidates)]
        got.append(candidates)
        have += len(candidates)
    return torch.cat(got)[:n]

"""The prior's box [low, high]: membership, and the one rule that densities are -inf outside it."""

from __future__ import annotations

import torch


def inside(theta: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """[...] bool: every coordinate of theta [..., D] lies in [low, high]."""
    return ((theta >= low) & (theta <= high)).all(-1)


def restrict_log_prob(log_prob: torch.Tensor, theta: torch.Tensor, low: torch.Tensor,
                      high: torch.Tensor) -> torch.Tensor:
    """log_prob where theta is inside the box, -inf outside it."""
    return torch.where(inside(theta, low, high), log_prob, torch.tensor(-torch.inf, dtype=log_prob.dtype))

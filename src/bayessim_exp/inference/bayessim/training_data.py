"""A round's simulations as the model sees them: summarized (diverged and non-finite rows dropped), split into
training rows and the held-out last `diagnostics.held_out_fraction` (coverage and gain checks), and which rows
replay the real actions as they were driven (collect: kept for the spread's calibration alone)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, get_args

import torch

from ...sim.trajectories import Trajectories


def summarized(collected: dict, summarize: Callable[[Trajectories], torch.Tensor], device) -> dict:
    """The collect stage's artifact summarized: theta, x and exact of the rows kept, and how many were dropped."""
    traj = Trajectories(**collected["traj"]).to(device)
    keep = ~traj.diverged
    x = summarize(traj.select(keep)).cpu()
    finite = torch.isfinite(x).all(1)
    theta = collected["theta"][keep.cpu()][finite]
    exact = collected.get("exact", torch.zeros(len(keep), dtype=torch.bool))[keep.cpu()][finite]
    return {"theta": theta, "x": x[finite], "exact": exact, "diverged": int((~keep).sum()) + int((~finite).sum())}


def held_out_count(n: int, fraction: float) -> int:
    return int(fraction * n)


def split(summary: dict, fraction: float) -> tuple[torch.Tensor, ...]:
    """(theta, x) for training and (theta, x) held out for the checks (the last rows)."""
    cut = len(summary["theta"]) - held_out_count(len(summary["theta"]), fraction)
    return summary["theta"][:cut], summary["x"][:cut], summary["theta"][cut:], summary["x"][cut:]


def exact_training_rows(summary: dict, fraction: float) -> torch.Tensor:
    """[rows of split's training part] bool: those replayed as the real data were driven (collect)."""
    n = len(summary["theta"])
    exact = summary.get("exact", torch.zeros(n, dtype=torch.bool))  # absent from rounds summarized before
    return exact[: n - held_out_count(n, fraction)]


CalibrateOn = Literal["latest", "all"]  # method.calibrate_on's choices
CALIBRATE_ON = get_args(CalibrateOn)


def calibration_rows(total: int, latest: int, calibrate_on: str) -> torch.Tensor:
    """[total] bool: the pooled training rows the model's spread is calibrated on, the last `latest` being the latest
    round's. latest: the latest round's pairs, drawn like the pairs the posterior is used on (one factor per parameter
    fitted to rounds pooled from several proposals would fit the wide early ones); all: every round's
    (docs/benchmarks.md: where the latest round's pairs miss the truth)."""
    rows = torch.zeros(total, dtype=torch.bool)
    rows[total - latest if calibrate_on == "latest" else 0:] = True
    return rows

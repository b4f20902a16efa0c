"""Model mismatch: real data that the simulator, at any parameters the posterior allows, does not reproduce.

Three signs, each recorded in results.json under `mismatch` and logged as a warning when present:
- `summaries_outside`: real summary features outside the range of the round's simulated training
  summaries (q extrapolates there), more of them than the round's held-out simulations have: the
  p-value is the real summary's rank among the held-out ones' counts, exact (uniform) when the real
  summary is exchangeable with them, whatever the features' correlations; flagged below alpha / n;
- `replay`: the replays near the posterior leave more of a real trajectory unexplained than of each other,
  and a sizeable share of its distance to the prior's replays (diagnostics/replayed_check.py);
- `dispersion`: the per-trajectory posteriors disagree beyond their widths (Cochran's Q, chi^2
  p-value below alpha; inference/bayessim/combination.py).
docs/statistics.md says what a user can do about each, and what the false-alarm rate was measured to be.
"""

from __future__ import annotations

import logging

import torch

log = logging.getLogger(__name__)


def summaries_outside(x_real: torch.Tensor, x_train: torch.Tensor, x_held: torch.Tensor) -> dict:
    """Per real summary [n, F]: how many features lie outside [min, max] of the simulated training summaries
    [m, F], and the share (1 + #held-out summaries with as many or more) / (held-out + 1): the p-value of so
    many under exchangeability with the held-out simulations [k, F]."""
    low, high = x_train.min(0).values, x_train.max(0).values

    def outside(x: torch.Tensor) -> torch.Tensor:
        return ((x < low) | (x > high)).sum(1)

    counts, null = outside(x_real), outside(x_held)
    p_values = [float((1 + (null >= c).sum()) / (len(null) + 1)) for c in counts]
    return {"features_outside": counts.tolist(), "p_value": p_values}


def flag_outside(outside: dict, alpha: float) -> dict:
    """summaries_outside's record with `flagged`: the real summaries whose p-value is below alpha / n (Bonferroni
    over the n real summaries); none with alpha 0."""
    n = len(outside["p_value"])
    return {**outside, "flagged": [i for i, p in enumerate(outside["p_value"]) if alpha > 0 and p < alpha / n]}


def mismatch_report(round_index: int, outside: dict, replay: dict | None, dispersion: dict | None,
                    alpha: float) -> dict:
    """results.json's `mismatch` entry; logs a warning naming every sign found."""
    reasons = []
    far = flag_outside(outside, alpha)["flagged"]
    if far:
        reasons.append(f"real summaries {far} have {[outside['features_outside'][i] for i in far]} features outside "
                       "the range of the simulated summaries")
    if replay is not None and replay["flagged"]:
        bad = replay["flagged"]
        ratios = [round(replay["excess_ratio"][i], 2) for i in bad]
        reasons.append(f"no parameter near the posterior reproduces real trajectories {bad}: what the replays leave "
                       f"unexplained is {ratios} of their distance to the prior's replays (more than "
                       f"{replay['max_distance_ratio']:g})")
    if dispersion is not None and dispersion["p_value"] < alpha:
        reasons.append(f"the per-trajectory posteriors disagree (Birge ratio {dispersion['birge_ratio']:.2f}, "
                       f"chi2 p = {dispersion['p_value']:.2g})")
    if reasons:
        log.warning("round %d: possible model mismatch: %s. See docs/statistics.md, 'Model mismatch'",
                    round_index, "; ".join(reasons))
    return {"flagged": bool(reasons), "reasons": reasons, "summaries_outside": outside}

"""Model mismatch: real data that the simulator, at any parameters the posterior allows, does not reproduce.

Three signs, each recorded in results.json under `mismatch` and logged as a warning when present:
- `summaries_outside`: real summary features outside the range of the round's m simulated summaries
  (q extrapolates there). A real summary exchangeable with the simulated ones has each of its F
  features outside with probability 2 / (m + 1); the count is flagged when a binomial(F, 2 / (m + 1))
  count that large has probability below alpha / n;
- `replay`: a real trajectory farther from every posterior replay than those lie from each other,
  by a sizeable share of its distance to the prior's replays (diagnostics/replayed_check.py);
- `dispersion`: the per-trajectory posteriors disagree beyond their widths (Cochran's Q, chi^2
  p-value below alpha; inference/bayessim/combination.py).
docs/statistics.md says what a user can do about each.
"""

from __future__ import annotations

import logging

import torch

log = logging.getLogger(__name__)


def summaries_outside(x_real: torch.Tensor, x_sim: torch.Tensor) -> dict:
    """Per real summary [n, F]: how many features lie outside [min, max] of the simulated summaries [m, F],
    and the binomial tail probability of so many (see the module docstring)."""
    low, high = x_sim.min(0).values, x_sim.max(0).values
    counts = ((x_real < low) | (x_real > high)).sum(1)
    chance = 2.0 / (len(x_sim) + 1)
    p_values = [_binomial_tail(int(c), x_real.shape[1], chance) for c in counts]
    return {"features_outside": counts.tolist(), "p_value": p_values}


def _binomial_tail(count: int, trials: int, chance: float) -> float:
    """P(X >= count) for X ~ binomial(trials, chance)."""
    if count <= 0:  # binom.sf's own value, without importing scipy.stats (0.3 s) in the usual case
        return 1.0
    from scipy.stats import binom

    return float(binom.sf(count - 1, trials, chance))


def mismatch_report(round_index: int, outside: dict, replay: dict | None, dispersion: dict | None,
                    alpha: float) -> dict:
    """results.json's `mismatch` entry; logs a warning naming every sign found."""
    reasons = []
    n = len(outside["p_value"])
    far = [i for i, p in enumerate(outside["p_value"]) if p < alpha / n]
    if far:
        reasons.append(f"real summaries {far} have {[outside['features_outside'][i] for i in far]} features outside "
                       "the range of the simulated summaries")
    if replay is not None and replay["flagged"]:
        bad = replay["flagged"]
        ratios = [round(replay["distance_posterior"][i] / replay["distance_prior"][i], 2) for i in bad]
        reasons.append(f"real trajectories {bad} lie farther from every posterior replay than the replays lie from "
                       f"each other, at {ratios} of their distance to the prior's replays")
    if dispersion is not None and dispersion["p_value"] < alpha:
        reasons.append(f"the per-trajectory posteriors disagree (Birge ratio {dispersion['birge_ratio']:.2f}, "
                       f"chi2 p = {dispersion['p_value']:.2g})")
    if reasons:
        log.warning("round %d: possible model mismatch: %s. See docs/statistics.md, 'Model mismatch'",
                    round_index, "; ".join(reasons))
    return {"flagged": bool(reasons), "reasons": reasons, "summaries_outside": outside}

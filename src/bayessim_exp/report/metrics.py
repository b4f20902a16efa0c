"""What the report compares: per-job metrics from results.json and their mean and 95 % interval over seeds."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

CONFIDENCE = 0.95


@dataclasses.dataclass(frozen=True)
class Metric:
    key: str
    label: str
    reference: float | None = None  # drawn as a dashed line: what a perfect or null result gives
    bounds: tuple[float, float] = (-math.inf, math.inf)  # the interval is clipped to the metric's range


def job_metrics(results: dict) -> dict[str, float | None]:
    """The final round's metrics of one finished job (None where the run did not measure it)."""
    rounds = results["rounds"]
    last = rounds[-1]
    post_std, prior_std = last.get("posterior_std") or {}, last.get("prior_std") or {}
    ratios = [post_std[n] / prior_std[n] for n in post_std if prior_std.get(n)]
    out = {
        "log_prob_gain": last.get("log_prob_gain"),
        "std_ratio": float(np.mean(ratios)) if ratios else None,
    }
    for kind, levels in sorted((last.get("coverage") or {}).items()):
        for level, value in sorted(levels.items(), key=lambda kv: float(kv[0])):
            out[f"coverage_{kind}_{level}"] = value
    out["surrogate_real_return"] = (last.get("surrogate_real_return") or {}).get("mean")  # rl/component.py record()
    out["wall_seconds"] = float(sum(sum((r.get("seconds") or {}).values()) for r in rounds))
    return out


def gain_by_round(results: dict) -> list[float | None]:
    return [r.get("log_prob_gain") for r in results["rounds"]]


def metrics_present(per_job: list[dict[str, float | None]]) -> list[Metric]:
    """The metrics measured by at least one job, in table order, with labels and reference lines."""
    keys = []
    for m in per_job:
        keys += [k for k, v in m.items() if v is not None and k not in keys]
    out = []
    for key in keys:
        if key == "log_prob_gain":
            out.append(Metric(key, "log-density gain at the true parameters (nats)", 0.0))
        elif key == "std_ratio":
            out.append(Metric(key, "posterior std / prior std (mean over parameters)", 1.0, (0.0, math.inf)))
        elif key.startswith("coverage_"):
            _, kind, level = key.split("_", 2)
            out.append(Metric(key, f"coverage of the {kind.upper()} {float(level):.0%} region", float(level), (0.0, 1.0)))
        elif key == "surrogate_real_return":
            out.append(Metric(key, "return on the surrogate real system"))
        elif key == "wall_seconds":
            out.append(Metric(key, "wall time per job (s)", None, (0.0, math.inf)))
        else:
            out.append(Metric(key, key))
    return out


def interval(values: list[float], bounds: tuple[float, float] = (-math.inf, math.inf)) -> tuple[float, float, float]:
    """Mean over seeds and the Student-t 95 % confidence interval of that mean (nan with one seed),
    clipped to `bounds` (a coverage interval never leaves [0, 1])."""
    values = [v for v in values if v is not None and math.isfinite(v)]
    if not values:
        return math.nan, math.nan, math.nan
    mean = float(np.mean(values))
    if len(values) < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, len(values) - 1) * np.std(values, ddof=1) / math.sqrt(len(values)))
    return mean, max(mean - half, bounds[0]), min(mean + half, bounds[1])

"""SimOpt's trajectory discrepancy (Chebotar et al. 2019, eq. 4) between simulated and real observations.

    D = w_l1 * sum_t sum_d |W_d e_td| + w_l2 * sum_t sum_d (W_d e_td)^2,
    e = G_sigma * ((o_sim - o_real) / s),

over the observed dimensions d (all, or a configured subset: partial observations), with s_d the
standard deviation of dimension d over the real observations (so dimensions in different units count
alike before the weights W), and G_sigma a Gaussian filter along time (the paper's remedy for slightly
misaligned trajectories). The filter is linear, so filtering the difference is filtering both
trajectories. The edges repeat the first and last step (scipy.ndimage's mode "nearest") and the kernel
reaches `truncate` standard deviations each side, as scipy's gaussian_filter1d does.

Each simulated parameter sample is rolled out once per real trajectory (from its initial state); its cost
is the mean of D over the real trajectories.
"""

from __future__ import annotations

import dataclasses
import difflib
import logging
import math

import torch
import torch.nn.functional as F

from ...errors import ConfigError, DataError

log = logging.getLogger(__name__)


@dataclasses.dataclass
class DiscrepancyConfig:
    l1_weight: float  # w_l1
    l2_weight: float  # w_l2
    smoothing_sigma: float  # Gaussian filter's standard deviation in control steps (0: no smoothing)
    smoothing_truncate: float  # the filter reaches this many standard deviations each side
    observed: list[str] | None  # observation names compared (partial observations); None: all
    weights: dict[str, float]  # W per observation name; names left out weigh 1

    def validate(self) -> None:
        if self.l1_weight < 0 or self.l2_weight < 0 or self.l1_weight + self.l2_weight == 0:
            raise ConfigError(f"need l1_weight, l2_weight >= 0 and not both 0, got {self.l1_weight}, {self.l2_weight}")
        if self.smoothing_sigma < 0 or not self.smoothing_truncate > 0:
            raise ConfigError(f"need smoothing_sigma >= 0 and smoothing_truncate > 0, got "
                              f"{self.smoothing_sigma}, {self.smoothing_truncate}")
        bad = {k: v for k, v in self.weights.items() if not (v >= 0 and math.isfinite(v))}
        if bad:
            raise ConfigError(f"weights must be finite and >= 0, got {bad}")
        if self.observed is not None and not self.observed:
            raise ConfigError("observed is empty: name at least one observation, or null for all")


def gaussian_kernel(sigma: float, truncate: float) -> torch.Tensor:
    """The normalised kernel scipy.ndimage.gaussian_filter1d uses (radius int(truncate * sigma + 0.5))."""
    radius = int(truncate * sigma + 0.5)
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def smooth_in_time(x: torch.Tensor, sigma: float, truncate: float) -> torch.Tensor:
    """Gaussian filter of x [..., T, S] along T, edges repeated."""
    if sigma == 0:
        return x
    kernel = gaussian_kernel(sigma, truncate).to(x)
    radius = (len(kernel) - 1) // 2
    lead, (t, s) = x.shape[:-2], x.shape[-2:]
    flat = x.reshape(-1, t, s).transpose(1, 2).reshape(-1, 1, t)  # one channel per (trajectory, dimension)
    padded = torch.cat([flat[..., :1].expand(-1, -1, radius), flat, flat[..., -1:].expand(-1, -1, radius)], -1)
    out = F.conv1d(padded, kernel.flip(0).view(1, 1, -1))
    return out.reshape(-1, s, t).transpose(1, 2).reshape(*lead, t, s)


class Discrepancy:
    """Cost of simulated observations against fixed real ones: `cost(sim [N, M, T+1, S]) -> [N]`."""

    def __init__(self, cfg: DiscrepancyConfig, obs_names: tuple[str, ...] | list[str], real_states: torch.Tensor):
        cfg.validate()
        self.cfg = cfg
        names = list(obs_names)
        if real_states.ndim != 3 or real_states.shape[-1] != len(names):
            raise DataError(f"real observations must be [M, T+1, {len(names)}] ({', '.join(names)}), "
                            f"got {tuple(real_states.shape)}")
        if not torch.isfinite(real_states).all():
            raise DataError("real observations contain NaN or inf")
        observed = names if cfg.observed is None else list(cfg.observed)
        for name in [*observed, *cfg.weights]:
            if name not in names:
                close = difflib.get_close_matches(name, names, n=3)
                hint = f" (did you mean {', '.join(close)}?)" if close else ""
                raise ConfigError(f"discrepancy: {name!r} is not an observation of this task{hint}; "
                                  f"observations: {', '.join(names)}")
        self.index = torch.tensor([names.index(n) for n in observed])
        self.weights = torch.tensor([cfg.weights.get(n, 1.0) for n in observed], dtype=torch.float64)
        self.real = real_states.double()[..., self.index]
        if self.real.shape[1] < 2:
            raise DataError("real observations need at least 2 time steps")
        spread = self.real.reshape(-1, len(observed)).std(0)
        flat = [n for n, s in zip(observed, spread.tolist()) if s == 0]
        if flat:
            log.warning("discrepancy: real %s never varies; compared unnormalised", ", ".join(flat))
        self.scale = torch.where(spread > 0, spread, torch.ones_like(spread))

    def __call__(self, sim_states: torch.Tensor) -> torch.Tensor:
        """sim_states [N, M, T+1, S]: sample i rolled out from real trajectory j's start -> cost [N]."""
        m, t1 = self.real.shape[:2]
        if sim_states.ndim != 4 or sim_states.shape[1:3] != (m, t1):
            raise DataError(f"simulated observations must be [N, {m}, {t1}, S] to match the real ones, "
                            f"got {tuple(sim_states.shape)}")
        diff = (sim_states.double()[..., self.index] - self.real) / self.scale
        e = smooth_in_time(diff, self.cfg.smoothing_sigma, self.cfg.smoothing_truncate) * self.weights
        per_real = self.cfg.l1_weight * e.abs().sum((-2, -1)) + self.cfg.l2_weight * (e**2).sum((-2, -1))
        return per_real.mean(1)

"""The least-squares residual sysid minimises: simulated minus real observations, every real trajectory replayed
from its recorded initial state under its recorded actions (diagnostics/replay.py), at the parameters u.

The parameters enter in unit coordinates of the prior's box, u = (theta - low) / (high - low) in [0, 1]^D, so one
finite-difference step and one optimiser tolerance suit parameters in any units. Each observation dimension is
divided by its standard deviation over the real data, so dimensions in different units count alike and the
residuals' noise is in units of each observation's spread. Steps after a real episode ended (`valid` False) carry
no information and are left out; a replay that ends earlier than its real trajectory holds its last observation
(Simulator.rollout), a mismatch the residual counts. mujoco.minimize evaluates many points at once (its
finite-difference Jacobian asks for D columns): they are simulated in one batch.
"""

from __future__ import annotations

import difflib

import numpy as np
import torch

from ...diagnostics.replay import replay
from ...errors import ConfigError, DataError
from ...sim.pool import SimulatorPool
from ...sim.trajectories import Trajectories


class ReplayResidual:
    """r(u): u [D] -> [R], or u [D, k] -> [R, k]; NaN where a simulation diverged. Counts its simulations."""

    def __init__(self, sims: SimulatorPool, real: Trajectories, low: np.ndarray, high: np.ndarray,
                 observed: list[str] | None):
        names = list(sims.task.obs_names)
        chosen = names if observed is None else list(observed)
        if not chosen:
            raise ConfigError("method.observed is empty: name at least one observation, or null for all")
        for name in chosen:
            if name not in names:
                close = difflib.get_close_matches(name, names, n=3)
                hint = f" (did you mean {', '.join(close)}?)" if close else ""
                raise ConfigError(f"method.observed: {name!r} is not an observation of task {sims.task.name}{hint}; "
                                  f"observations: {', '.join(names)}")
        states = real.states.double().cpu()
        if not torch.isfinite(states).all():
            raise DataError("real observations contain NaN or inf")
        self.sims, self.real = sims, real
        self.low, self.span = np.asarray(low, np.float64), np.asarray(high, np.float64) - np.asarray(low, np.float64)
        self.index = torch.tensor([names.index(n) for n in chosen])
        self.mask = real.valid.bool().cpu()  # [M, T]: states[:, t + 1] was reached under actions[:, t]
        if not self.mask.any():
            raise DataError("the real trajectories have no valid step to fit")
        observed_states = states[..., self.index]
        reached = torch.cat([observed_states[:, 0], observed_states[:, 1:][self.mask]], 0)  # [starts + valid steps, S']
        spread = reached.std(0)
        self.scale = torch.where(spread > 0, spread, torch.ones_like(spread))  # a constant observation: unscaled
        self.target = observed_states[:, 1:][self.mask]  # [valid steps, S']
        self.simulations = 0
        self.diverged = 0

    @property
    def size(self) -> int:
        """Residuals per parameter point."""
        return self.target.numel()

    def theta(self, u: np.ndarray) -> np.ndarray:
        """Parameters in their units for unit coordinates u [..., D]."""
        return self.low + self.span * np.asarray(u, np.float64)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, np.float64)
        columns = u.reshape(len(self.low), -1).T  # [k, D]
        m = self.real.num
        # the optimiser stays inside [0, 1]; the clip only guards against rounding at the edges
        params = torch.as_tensor(self.theta(np.clip(columns, 0.0, 1.0))).repeat_interleave(m, 0)
        which = torch.arange(m).repeat(len(columns))
        sim = replay(self.sims, params, self.real, which)
        self.simulations += len(params)
        self.diverged += int(sim.diverged.sum())
        k = len(columns)
        states = sim.states.double().cpu()[:, 1:][..., self.index].reshape(k, m, self.mask.shape[1], -1)
        diff = (states[:, self.mask] - self.target) / self.scale  # [k, valid steps, S']
        broken = sim.diverged.cpu().reshape(k, m)[:, :, None].expand(k, m, self.mask.shape[1])[:, self.mask]
        diff = torch.where(broken[..., None], torch.nan, diff)
        out = diff.reshape(k, -1).T.numpy()
        return out[:, 0] if u.ndim == 1 else out

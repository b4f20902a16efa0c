"""Where 'real' trajectories come from: a surrogate environment with hidden parameters, or a file.

File format (npz), written by `save_trajectories` or by a robot's logging code:
    states   [n, T+1, S]  float, observations in the task's order (Task.obs_names)
    actions  [n, T, A]    float, normalised to [-1, 1] as the task's actions
    dt       scalar       optional, control timestep in seconds (checked against the task)
    valid    [n, T]       optional bool, False after an episode ended early
    params, param_names   optional, the true parameters if known: used only to score the
                          posterior in results.json, never by the inference
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch

from .errors import ConfigError, DataError
from .registry import register
from .sim.pool import SimulatorPool
from .sim.trajectories import Trajectories
from .tasks.base import Task


@dataclasses.dataclass
class SurrogateConfig:
    per_round: int

    def validate(self) -> None:
        if self.per_round < 1:
            raise ConfigError(f"per_round must be >= 1, got {self.per_round}")


@dataclasses.dataclass
class FileConfig:
    path: str


class SurrogateReal:
    """A simulated 'real' system with the task's real_params, which the inference never sees."""

    def __init__(self, cfg: SurrogateConfig, task: Task, sims: SimulatorPool):
        self.cfg, self.task, self.sims = cfg, task, sims
        self.true_params: np.ndarray | None = task.real_values

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories:
        params = np.repeat(self.true_params[None], self.cfg.per_round, 0)
        traj = self.sims.get(self.cfg.per_round).rollout(params, policy, horizon, seed)
        if traj.diverged.any():
            raise DataError("the surrogate real system diverged; check the task's real_params")
        return traj


class FileReal:
    """Trajectories recorded on a real system, all given in the first round."""

    def __init__(self, cfg: FileConfig, task: Task):
        if cfg.path in ("???", ""):
            raise ConfigError("real=file needs real.path=<file.npz> (format: README.md, 'Real data from a robot')")
        self.path = Path(cfg.path).expanduser()
        if not self.path.is_file():
            raise ConfigError(f"real.path={cfg.path!r}: no such file")
        self.task = task
        with np.load(self.path, allow_pickle=False) as data:
            self._data = {k: data[k] for k in data.files}
        self.true_params = self._true_params()

    def _true_params(self) -> np.ndarray | None:
        if "params" not in self._data:
            return None
        names = [str(n) for n in self._data.get("param_names", self.task.spec.names)]
        values = dict(zip(names, np.asarray(self._data["params"], dtype=float).ravel()))
        if set(values) != set(self.task.spec.names):
            return None  # recorded for other parameters: nothing to score against
        return np.array([values[n] for n in self.task.spec.names])

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories | None:
        if round_index > 1:
            return None
        return load_trajectories(self._data, self.task, horizon, str(self.path))


def load_trajectories(data: dict, task: Task, horizon: int, where: str) -> Trajectories:
    """Validate recorded arrays against the task and cut them to `horizon` control steps."""
    for key in ("states", "actions"):
        if key not in data:
            raise DataError(f"{where}: missing array {key!r}; found {sorted(data)}")
    states, actions = np.asarray(data["states"], float), np.asarray(data["actions"], float)
    if states.ndim != 3 or states.shape[2] != task.obs_dim:
        raise DataError(
            f"{where}: states must be [n, T+1, {task.obs_dim}] ({', '.join(task.obs_names)}) for task "
            f"{task.name}, got {states.shape}"
        )
    n, t1, _ = states.shape
    if actions.shape != (n, t1 - 1, task.action_dim):
        raise DataError(f"{where}: actions must be [{n}, {t1 - 1}, {task.action_dim}], got {actions.shape}")
    if "dt" in data and not np.isclose(float(data["dt"]), task.cfg.control_dt, rtol=1e-6):
        raise DataError(f"{where}: recorded at dt={float(data['dt'])} s but task {task.name} runs at {task.cfg.control_dt} s")
    if t1 - 1 < horizon:
        raise DataError(f"{where}: trajectories have {t1 - 1} steps, fewer than collect.horizon={horizon}")
    if not (np.isfinite(states).all() and np.isfinite(actions).all()):
        raise DataError(f"{where}: states or actions contain NaN or inf")
    if np.abs(actions).max(initial=0.0) > 1.0 + 1e-6:
        raise DataError(f"{where}: actions must be normalised to [-1, 1]; max |a| = {np.abs(actions).max():.3g}")
    valid = np.asarray(data.get("valid", np.ones((n, t1 - 1), bool)), bool)
    traj = Trajectories(
        torch.as_tensor(states, dtype=torch.float32), torch.as_tensor(actions, dtype=torch.float32),
        torch.zeros(n, t1 - 1), torch.as_tensor(valid), torch.zeros(n, dtype=torch.bool), task.cfg.control_dt,
    )
    return traj.truncate(horizon)


def save_trajectories(path: str | Path, traj: Trajectories, params: np.ndarray | None = None,
                      param_names: list[str] | None = None) -> None:
    """Write trajectories in the format `real=file` reads."""
    arrays = {"states": traj.states.numpy(), "actions": traj.actions.numpy(), "valid": traj.valid.numpy(),
              "dt": np.array(traj.dt)}
    if params is not None:
        arrays["params"] = np.asarray(params, float)
        arrays["param_names"] = np.array(param_names or [])
    np.savez(path, **arrays)


@register("real", "surrogate", SurrogateConfig)
def surrogate(cfg: SurrogateConfig, task: Task, sims: SimulatorPool) -> SurrogateReal:
    return SurrogateReal(cfg, task, sims)


@register("real", "file", FileConfig)
def from_file(cfg: FileConfig, task: Task, sims: SimulatorPool) -> FileReal:
    return FileReal(cfg, task)

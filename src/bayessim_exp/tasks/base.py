"""Task: what a robot learning problem is, independent of the simulation backend.

A task owns its MJCF, the observation/action/reward/termination functions (array code written
against an array namespace `xp`, numpy on CPU), the reset distribution, control rate, episode
length, its default ParamSpec and the surrogate-real parameter values.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from ..errors import ConfigError
from .params import ParamConfig, ParamSpec, nominal_value, param_config

ASSETS = Path(__file__).parent / "assets"


@dataclasses.dataclass
class TaskConfig:
    """Fields every task config has; tasks subclass it to add their own."""

    parameters: dict[str, ParamConfig]
    # the surrogate 'real' system's hidden values; a parameter left out takes its nominal value (the MJCF as written)
    real_params: dict[str, float]
    control_dt: float
    episode_length: int

    def validate(self) -> None:
        if not self.parameters:
            raise ConfigError("parameters is empty: declare at least one parameter to infer")
        extra = [n for n in self.real_params if n not in self.parameters]
        if extra:
            raise ConfigError(f"real_params names unknown parameters {extra}; parameters: {', '.join(self.parameters)}")
        for name, value in self.real_param_values().items():
            low, high = self.parameters[name].range
            if not low <= value <= high:
                given = "" if name in self.real_params else " (its nominal value, as no real_params entry gives one)"
                raise ConfigError(f"real_params.{name}={value}{given} lies outside its range [{low}, {high}]")
        if self.control_dt <= 0 or self.episode_length < 1:
            raise ConfigError("control_dt must be > 0 and episode_length >= 1")

    def real_param_values(self) -> dict[str, float]:
        """Every parameter's surrogate-real value: real_params where given, else the nominal value."""
        out = {}
        for name, raw in self.parameters.items():
            p = param_config(name, raw)
            out[name] = float(self.real_params.get(name, nominal_value(p.operation, p.nominal)))
        return out


class Task:
    """Base class. Subclasses set `name`, `xml` (or override `model_path`), `obs_names`, `data_fields` and the hooks."""

    name: str = ""
    xml: str = ""  # file name under tasks/assets
    has_reward: bool = True  # False: the task defines no reward (rewards are 0) and RL refuses it
    obs_names: tuple[str, ...] = ()
    # MjData fields observe() reads; state fields (qpos, qvel, ...) are always current,
    # derived ones (xpos, sensordata, ...) make the simulator compute positions and velocities
    data_fields: tuple[str, ...] = ("qpos", "qvel")

    def __init__(self, cfg: TaskConfig):
        self.cfg = cfg
        self.spec = ParamSpec.from_config(cfg.parameters, self.model)
        steps = cfg.control_dt / self.model.opt.timestep
        self.frame_skip = int(round(steps))
        if self.frame_skip < 1 or abs(steps - self.frame_skip) > 1e-6:
            raise ConfigError(
                f"control_dt={cfg.control_dt} is not a whole multiple of the model timestep {self.model.opt.timestep}"
            )
        lo, hi = self.model.actuator_ctrlrange.T
        self._ctrl_mid, self._ctrl_half = (hi + lo) / 2, (hi - lo) / 2

    @functools.cached_property
    def model(self) -> mujoco.MjModel:
        path = self.model_path
        try:
            return mujoco.MjModel.from_xml_path(str(path))
        except ValueError as exc:  # MuJoCo's parse and compile errors
            raise ConfigError(f"MuJoCo cannot load {path}: {exc}") from None

    @property
    def model_path(self) -> Path:
        """The MJCF file: `xml` under tasks/assets for the built-in tasks."""
        return ASSETS / self.xml

    @property
    def obs_dim(self) -> int:
        return len(self.obs_names)

    @property
    def actuators(self) -> np.ndarray:
        """Ids of the actuators the actions drive, in action order: every actuator of the built-in tasks."""
        return np.arange(self.model.nu)

    @property
    def action_names(self) -> tuple[str, ...]:
        """The driven actuators' names (their index where the MJCF names none), in action order."""
        return tuple(mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or str(i) for i in self.actuators)

    @property
    def action_dim(self) -> int:
        return len(self.actuators)

    @property
    def true_params(self) -> np.ndarray:
        """The surrogate real system's parameters as the task's YAML gives them (real_params, the nominal where left
        out), in spec order; real=surrogate's `truth=prior` draws others."""
        values = self.cfg.real_param_values()
        return np.array([values[n] for n in self.spec.names])

    def ctrl(self, action: Any, xp: Any = np) -> Any:
        """Normalised actions in [-1, 1] -> actuator controls in the ctrlrange (xp: the backend's array namespace)."""
        return self._ctrl_mid + self._ctrl_half * xp.clip(action, -1.0, 1.0)

    # hooks, batched over environments ------------------------------------------------
    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        """Initial values [n, ...] of MjData state fields (qpos, qvel, mocap_pos, mocap_quat, ...).

        Fields left out keep the model's defaults (qpos0, zero velocities)."""
        return {"qpos": np.repeat(self.model.qpos0[None], n, 0), "qvel": np.zeros((n, self.model.nv))}

    def state_from_observation(self, obs: np.ndarray) -> dict[str, np.ndarray] | None:
        """The MjData state fields [n, ...] whose observation is obs [n, S], where the observation
        determines the state (SimOpt and the replayed predictive check restart simulations from real
        initial states); None otherwise."""
        return None

    def observe(self, d: Any, xp: Any = np) -> Any:
        raise NotImplementedError

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        """Reward of taking `action` in `obs` and landing in `next_obs`: [N]."""
        raise NotImplementedError

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        """True where the episode ends in `obs`: [N]."""
        return xp.zeros(obs.shape[0], dtype=bool)

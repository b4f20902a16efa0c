"""task=mjcf: a task from any MJCF file, configured in YAML only (conf/task/mjcf.yaml, README "Your own robot").

The YAML names the model file (`xml`: a path, or pkg://<package>/<path inside it> for a model an
installed package ships), what is observed (joint positions and velocities by joint name, named
sensors), what the actions drive (named actuators, each action in [-1, 1] mapped onto its ctrlrange;
actuators left out hold ctrl 0), the initial state (a keyframe or qpos0, with optional uniform noise),
and optionally a reward and termination bounds on named observations. Where the observations hold
every joint's position and velocity, a recorded observation gives back the simulator state, so
simulations and replays start where each real trajectory started.

Observation names (the order of the observation vector): `<joint>_pos` and `<joint>_vel` for the joints
listed under qpos and qvel (`<joint>_pos_<k>` for the several entries of ball and free joints), then
`<sensor>` (`<sensor>_<k>` for sensors of several values). Action names are the actuators' names.
"""

from __future__ import annotations

import dataclasses
import difflib
import fnmatch
import importlib.util
import logging
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from ..errors import ConfigError
from .base import Task, TaskConfig

PACKAGE_SCHEME = "pkg://"
_QPOS_WIDTH = {mujoco.mjtJoint.mjJNT_FREE: 7, mujoco.mjtJoint.mjJNT_BALL: 4,
               mujoco.mjtJoint.mjJNT_SLIDE: 1, mujoco.mjtJoint.mjJNT_HINGE: 1}
_DOF_WIDTH = {mujoco.mjtJoint.mjJNT_FREE: 6, mujoco.mjtJoint.mjJNT_BALL: 3,
              mujoco.mjtJoint.mjJNT_SLIDE: 1, mujoco.mjtJoint.mjJNT_HINGE: 1}
log = logging.getLogger(__name__)


@dataclasses.dataclass
class RewardConfig:
    """reward = -sum_o weights[o] (o - targets[o])^2 - action_cost |action|^2 over the next observation."""

    targets: dict[str, float]  # observation name -> the value it should take
    weights: dict[str, float]  # observation name -> weight of its squared error (the same names as targets)
    action_cost: float  # weight of the squared normalised actions


@dataclasses.dataclass
class MjcfConfig(TaskConfig):
    xml: str  # the MJCF: a file path (relative to the working directory) or pkg://<package>/<path inside it>
    qpos: list[str]  # joints whose positions are observed (names or shell patterns such as "*")
    qvel: list[str]  # joints whose velocities are observed
    sensors: list[str]  # sensors whose values are observed
    actuators: list[str]  # actuators the actions drive, in action order
    keyframe: str | None  # the keyframe the episodes start from; None: qpos0 at rest
    qpos_noise: float  # initial joint displacement ~ U(-q, q) per degree of freedom
    qvel_noise: float  # initial joint velocity ~ U(-v, v) per degree of freedom
    reward: RewardConfig | None  # None: no reward (rl=ppo refuses the task)
    termination: dict[str, Any]  # observation name -> [low, high]: the episode ends once one leaves its interval

    def validate(self) -> None:
        super().validate()
        if not self.actuators:
            raise ConfigError("actuators is empty: name at least one actuator the actions drive")
        if not (self.qpos or self.qvel or self.sensors):
            raise ConfigError("nothing is observed: name joints under qpos / qvel or sensors under sensors")
        if self.qpos_noise < 0 or self.qvel_noise < 0:
            raise ConfigError(f"qpos_noise and qvel_noise must be >= 0, got {self.qpos_noise}, {self.qvel_noise}")
        if self.reward is not None and set(self.reward.targets) != set(self.reward.weights):
            raise ConfigError(f"reward.targets and reward.weights must name the same observations; targets: "
                              f"{sorted(self.reward.targets)}, weights: {sorted(self.reward.weights)}")
        for name, bounds in self.termination.items():
            numbers = isinstance(bounds, list) and all(isinstance(b, (int, float)) for b in bounds)
            if not numbers or len(bounds) != 2 or not bounds[0] < bounds[1]:
                raise ConfigError(f"termination.{name} must be [low, high] with low < high, got {bounds!r}")


def model_file(xml: str) -> Path:
    """The MJCF file `xml` names: a path, or pkg://<package>/<path inside the package>. The package is
    found without importing it (a model package may be installed without its dependencies)."""
    if not xml.startswith(PACKAGE_SCHEME):
        path = Path(xml).expanduser()
        if not path.is_file():
            raise ConfigError(f"task.xml={xml!r}: no such file ({path.absolute()})")
        return path
    package, _, inner = xml[len(PACKAGE_SCHEME):].partition("/")
    if not package or not inner or "." in package:
        raise ConfigError(f"task.xml={xml!r}: write {PACKAGE_SCHEME}<top-level package>/<path inside it>, "
                          f"e.g. {PACKAGE_SCHEME}bayessim_exp/tasks/assets/two_link_arm/two_link_arm.xml")
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise ConfigError(f"task.xml={xml!r}: no installed package {package!r}")
    for root in spec.submodule_search_locations:
        if (Path(root) / inner).is_file():
            return Path(root) / inner
    raise ConfigError(f"task.xml={xml!r}: package {package!r} ({', '.join(spec.submodule_search_locations)}) "
                      f"has no file {inner}")


def _unknown(kind: str, name: str, known: list[str], where: str) -> ConfigError:
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    return ConfigError(f"{where}: unknown {kind} {name!r}{hint}; the {kind}s: {', '.join(known) or 'none'}")


def _named(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int, patterns: list[str], where: str) -> list[int]:
    """Ids of the objects that `patterns` (names or shell patterns) name, in the order given, each once."""
    kind = "keyframe" if obj == mujoco.mjtObj.mjOBJ_KEY else obj.name[6:].lower()
    names = [mujoco.mj_id2name(model, obj, i) or "" for i in range(count)]
    known = [n for n in names if n]
    ids: list[int] = []
    for pattern in patterns:
        if any(ch in pattern for ch in "*?["):
            found = [i for i, n in enumerate(names) if n and fnmatch.fnmatchcase(n, pattern)]
            if not found:
                raise ConfigError(f"{where}: pattern {pattern!r} matches no {kind}; the {kind}s: {', '.join(known)}")
        elif pattern in names:
            found = [names.index(pattern)]
        else:
            raise _unknown(kind, pattern, known, where)
        twice = [names[i] for i in found if i in ids]
        if twice:
            raise ConfigError(f"{where} names {kind} {twice[0]!r} twice")
        ids += found
    return ids


def _entry_names(base: str, width: int) -> list[str]:
    return [base] if width == 1 else [f"{base}_{k}" for k in range(width)]


def _observation_layout(m: mujoco.MjModel, cfg: MjcfConfig) -> tuple[list[str], tuple[np.ndarray, ...]]:
    """The observation's names, and the qpos, qvel and sensordata addresses its entries are read from (in
    that order: positions, velocities, sensors)."""
    names: list[str] = []
    qpos_cols, qvel_cols, sensor_cols = [], [], []
    for j in _named(m, mujoco.mjtObj.mjOBJ_JOINT, m.njnt, cfg.qpos, "qpos"):
        width = _QPOS_WIDTH[mujoco.mjtJoint(m.jnt_type[j])]
        qpos_cols += range(m.jnt_qposadr[j], m.jnt_qposadr[j] + width)
        names += _entry_names(f"{m.joint(j).name}_pos", width)
    for j in _named(m, mujoco.mjtObj.mjOBJ_JOINT, m.njnt, cfg.qvel, "qvel"):
        width = _DOF_WIDTH[mujoco.mjtJoint(m.jnt_type[j])]
        qvel_cols += range(m.jnt_dofadr[j], m.jnt_dofadr[j] + width)
        names += _entry_names(f"{m.joint(j).name}_vel", width)
    for s in _named(m, mujoco.mjtObj.mjOBJ_SENSOR, m.nsensor, cfg.sensors, "sensors"):
        if m.sensor_needstage[s] > int(mujoco.mjtStage.mjSTAGE_VEL):
            # the simulators recompute positions and velocities after a step, not accelerations and forces
            raise ConfigError(f"sensors: {m.sensor(s).name!r} ({mujoco.mjtSensor(m.sensor_type[s]).name[7:].lower()}) "
                              "reads accelerations or forces; only position and velocity sensors can be observed")
        sensor_cols += range(m.sensor_adr[s], m.sensor_adr[s] + m.sensor_dim[s])
        names += _entry_names(m.sensor(s).name, int(m.sensor_dim[s]))
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise ConfigError(f"observation names {clash} occur twice (a sensor named like a joint's _pos/_vel entry)")
    return names, tuple(np.array(c, int) for c in (qpos_cols, qvel_cols, sensor_cols))


class MjcfTask(Task):
    name = "mjcf"

    def __init__(self, cfg: MjcfConfig):
        self.cfg = cfg  # model_path reads it before Task.__init__ loads the model
        super().__init__(cfg)
        m = self.model
        names, (self._qpos_cols, self._qvel_cols, self._sensor_cols) = _observation_layout(m, cfg)
        self.obs_names = tuple(names)
        self.data_fields = ("qpos", "qvel", "sensordata") if self._sensor_cols.size else ("qpos", "qvel")
        self._state_from_obs = self._state_columns()

        acts = _named(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu, cfg.actuators, "actuators")
        unlimited = [m.actuator(a).name for a in acts if not m.actuator_ctrllimited[a]]
        if unlimited:
            raise ConfigError(f"actuators {unlimited} have no ctrlrange in the MJCF, and actions in [-1, 1] are "
                              "mapped onto it: give them ctrlrange (with ctrllimited) in the model")
        self._actuators = np.array(acts, int)
        held = [m.actuator(a).name for a in range(m.nu) if a not in acts]
        if held:
            log.info("task=mjcf: actuators %s are not driven by the actions; their ctrl stays 0", held)
        self._act_mid, self._act_half = self._ctrl_mid[acts], self._ctrl_half[acts]
        self._scatter = np.zeros((len(acts), m.nu))  # actions -> every actuator's ctrl, 0 for those not named
        self._scatter[np.arange(len(acts)), acts] = 1.0

        self._start = self._start_state(cfg.keyframe)
        self._reward = self._reward_terms(cfg.reward)
        bounds = {self._column(n, "termination"): [float(b) for b in v] for n, v in cfg.termination.items()}
        self._term_cols = np.array(list(bounds), int)
        self._term_low = np.array([b[0] for b in bounds.values()])
        self._term_high = np.array([b[1] for b in bounds.values()])

    @property
    def model_path(self) -> Path:
        return model_file(self.cfg.xml)

    @property
    def has_reward(self) -> bool:  # type: ignore[override]
        return self.cfg.reward is not None

    @property
    def actuators(self) -> np.ndarray:
        return self._actuators

    # set up ------------------------------------------------------------------------------------
    def _column(self, name: str, where: str) -> int:
        if name not in self.obs_names:
            raise _unknown("observation", name, list(self.obs_names), where)
        return self.obs_names.index(name)

    def _state_columns(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Observation columns holding qpos [nq] and qvel [nv], where every joint's position and velocity is
        observed and the model has no actuator activations (the state an observation cannot give)."""
        m = self.model
        qpos_at = dict(zip(self._qpos_cols.tolist(), range(len(self._qpos_cols))))
        offset = len(self._qpos_cols)
        qvel_at = dict(zip(self._qvel_cols.tolist(), range(offset, offset + len(self._qvel_cols))))
        if m.na or len(qpos_at) < m.nq or len(qvel_at) < m.nv:
            return None
        return np.array([qpos_at[i] for i in range(m.nq)]), np.array([qvel_at[i] for i in range(m.nv)])

    def _start_state(self, keyframe: str | None) -> dict[str, np.ndarray]:
        m = self.model
        if keyframe is None:
            return {"qpos": m.qpos0.copy(), "qvel": np.zeros(m.nv), "act": np.zeros(m.na)}
        k = _named(m, mujoco.mjtObj.mjOBJ_KEY, m.nkey, [keyframe], "keyframe")[0]
        return {"qpos": m.key_qpos[k].copy(), "qvel": m.key_qvel[k].copy(), "act": m.key_act[k].copy()}

    def _reward_terms(self, reward: RewardConfig | None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        if reward is None:
            return None
        names = list(reward.targets)
        cols = np.array([self._column(n, "reward.targets") for n in names], int)
        return cols, np.array([reward.targets[n] for n in names]), np.array([reward.weights[n] for n in names])

    # hooks ---------------------------------------------------------------------------------------
    def reset_state(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        m = self.model
        qpos = np.repeat(self._start["qpos"][None], n, 0)
        # displacements in the tangent space, so ball and free joints keep unit quaternions
        dq = rng.uniform(-self.cfg.qpos_noise, self.cfg.qpos_noise, (n, m.nv))
        for i in range(n):
            mujoco.mj_integratePos(m, qpos[i], dq[i], 1.0)
        qvel = self._start["qvel"][None] + rng.uniform(-self.cfg.qvel_noise, self.cfg.qvel_noise, (n, m.nv))
        state = {"qpos": qpos, "qvel": qvel}
        if m.na:
            state["act"] = np.repeat(self._start["act"][None], n, 0)
        return state

    def state_from_observation(self, obs: np.ndarray) -> dict[str, np.ndarray] | None:
        if self._state_from_obs is None:
            return None
        qpos_cols, qvel_cols = self._state_from_obs
        obs = np.asarray(obs, dtype=np.float64)
        return {"qpos": obs[:, qpos_cols], "qvel": obs[:, qvel_cols]}

    def observe(self, d: Any, xp: Any = np) -> Any:
        parts = [d.qpos[:, self._qpos_cols], d.qvel[:, self._qvel_cols]]
        if self._sensor_cols.size:
            parts.append(d.sensordata[:, self._sensor_cols])
        return xp.concatenate(parts, axis=-1)

    def ctrl(self, action: Any, xp: Any = np) -> Any:
        return (self._act_mid + self._act_half * xp.clip(action, -1.0, 1.0)) @ self._scatter

    def reward(self, obs: Any, action: Any, next_obs: Any, xp: Any = np) -> Any:
        if self._reward is None:
            return xp.zeros(obs.shape[0])
        cols, targets, weights = self._reward
        cost = ((next_obs[:, cols] - targets) ** 2) @ weights
        return -cost - self.cfg.reward.action_cost * xp.sum(xp.clip(action, -1.0, 1.0) ** 2, axis=-1)

    def terminated(self, obs: Any, xp: Any = np) -> Any:
        x = obs[:, self._term_cols]
        return xp.any((x < self._term_low) | (x > self._term_high), axis=-1)

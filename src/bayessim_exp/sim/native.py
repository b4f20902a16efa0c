"""CPU backend: N MuJoCo simulations with per-environment parameters on mujoco.batch.Batch."""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Sequence

import mujoco
import numpy as np
import torch
from mujoco import batch as mjbatch

from ..errors import ConfigError
from ..machine import usable_cpus
from ..tasks.base import Task
from ..tasks.params import ParamSpec
from .base import Simulator, broke_down
from .integrators import codes as integrator_codes

# warnings that mean the integration broke down (MuJoCo then silently resets the data)
_DIVERGENCE_WARNINGS = [
    int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)
]


def simulation_threads(nthread: int) -> int:
    """nthread, or for 0 the CPUs this process may run on (machine.usable_cpus), not the machine's count that
    mujoco.batch's own 0 means (64 threads in each of 8 processes on a 64-core machine)."""
    return nthread or usable_cpus()


@dataclasses.dataclass
class NativeConfig:
    nthread: int  # 0: the CPUs this process may run on
    max_abs_qvel: float  # a joint speed beyond this counts as diverged

    def validate(self) -> None:
        if self.nthread < 0 or self.max_abs_qvel <= 0:
            raise ConfigError("nthread must be >= 0 and max_abs_qvel > 0")


class NativeSimulator(Simulator):
    """`model`: what the slots simulate (default the task's model; sim=mjx passes its tuned model)."""

    def __init__(self, task: Task, num_envs: int, cfg: NativeConfig, model: mujoco.MjModel | None = None):
        super().__init__(task, num_envs)
        self.cfg = cfg
        self.model = task.model if model is None else model
        self.batch = mjbatch.Batch(self.model, num_envs, nthread=simulation_threads(cfg.nthread))
        derived = [f for f in task.data_fields if f not in ("qpos", "qvel", "act", "time")]
        self._stage = mujoco.mjtStage.mjSTAGE_VEL if derived else mujoco.mjtStage.mjSTAGE_NONE
        for field in task.data_fields:  # outputs are copied out only after calls made once they are bound
            self.batch.bind(field)
        self._obs = np.zeros((num_envs, task.obs_dim))

    def alternate_integrators(self, names: Sequence[str]) -> None:
        self.batch.expand("opt.integrator")[:] = np.resize(integrator_codes(names, self.model), self.num_envs)

    @classmethod
    def check_spec(cls, spec: ParamSpec) -> None:
        unsupported = [f for f in spec.fields if f not in mjbatch.MODEL_FIELDS]
        if unsupported:
            raise ConfigError(f"sim=native cannot set {', '.join(unsupported)} per simulation "
                              "(mujoco.batch.MODEL_FIELDS lists the fields it can)")

    @property
    def device(self) -> torch.device:
        return torch.device("cpu")

    def set_params(self, values: np.ndarray, ids: np.ndarray) -> None:
        for name, vals in self.task.spec.field_values(self.model, values).items():
            target = self.batch.expand(name)
            target[ids] = vals.reshape((len(ids),) + target.shape[1:])
        if self.task.spec.needs_set_const:
            self.batch.set_const(ids)

    def _reset(self, params: torch.Tensor, ids: torch.Tensor, state: dict[str, np.ndarray]) -> torch.Tensor:
        ids = ids.numpy()
        self.set_params(params.numpy(), ids)
        self.batch.reset(ids, stage=mujoco.mjtStage.mjSTAGE_NONE)
        for field, values in state.items():
            self.batch.bind(field)[ids] = values
        self.batch.forward(ids, stage=mujoco.mjtStage.mjSTAGE_VEL)
        self._obs[ids] = self._observe()[ids]
        return torch.as_tensor(self._obs[ids], dtype=torch.float32)

    def _step(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        act = actions.detach().cpu().numpy().astype(np.float64)
        self.batch.ctrl[:] = self.task.ctrl(act)
        before = self._warnings()
        broken = np.zeros(self.num_envs, dtype=bool)
        try:
            self.batch.step(nstep=self.task.frame_skip, stage=self._stage)
        except mjbatch.SimulationError as exc:
            broken[exc.ids] = True
        broken |= self._warnings() > before
        broken |= broke_down(self.batch.qpos, self.batch.qvel, self.cfg.max_abs_qvel)
        obs = self._observe()
        # a slot that broke down keeps its last finite observation
        obs = np.where(broken[:, None] | self.diverged.numpy()[:, None], self._obs, obs)
        reward = self.task.reward(self._obs, act, obs)
        terminated = np.asarray(self.task.terminated(obs), dtype=bool)
        self._obs = obs
        return (torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(reward, dtype=torch.float32),
                torch.as_tensor(terminated), torch.as_tensor(broken))

    def _observe(self) -> np.ndarray:
        d = types.SimpleNamespace(**{f: self.batch.bind(f) for f in self.task.data_fields})
        return np.asarray(self.task.observe(d), dtype=np.float64)

    def _warnings(self) -> np.ndarray:
        # per simulation: [warning, (lastinfo, number)]
        return self.batch.warning[:, _DIVERGENCE_WARNINGS, 1].sum(1)


def native_backend(cfg: NativeConfig):
    """The sim group builds a factory: (task, num_envs) -> simulator."""
    return lambda task, num_envs: NativeSimulator(task, num_envs, cfg)

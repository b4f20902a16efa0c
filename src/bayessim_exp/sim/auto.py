"""sim=auto: MJX when JAX sees a GPU, native MuJoCo on CPU threads otherwise, and native MuJoCo on a GPU
machine too for a task whose tuning lists the MJX implementation found there in `native_faster_on` (native
measured faster: docs/benchmarks.md; benchmarks/auto_choice.py prints auto_choice's answers beside the rates)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from ..tasks.base import Task
from .base import Simulator
from .mjx import MjxConfig, mjx_backend
from .mjx_impl import resolve_impl
from .mjx_setup import gpu_visible
from .mjx_tuning import native_measured_faster
from .native import NativeConfig, native_backend

log = logging.getLogger(__name__)
_LOGGED: set[tuple[str, str]] = set()  # (task, implementation) whose native choice was reported


def auto_choice(impl: str, tuning: Mapping[str, Any]) -> str:
    """sim=auto's simulator on a machine whose GPU JAX sees, where sim.impl resolves to MJX's implementation
    `impl` (jax, warp): "native" where the task's tuning lists `impl` in native_faster_on, else "mjx"."""
    return "native" if native_measured_faster(impl, tuning) else "mjx"


def simulates_on_mjx(sim: Mapping[str, Any]) -> bool:
    """Whether a run's large batches simulate on MJX under the sim config `sim` on this machine."""
    if sim.get("name") == "mjx":
        return True
    if sim.get("name") != "auto" or not gpu_visible():
        return False
    return auto_choice(resolve_impl(sim["impl"], sim["tuning"]), sim["tuning"]) == "mjx"


def auto_backend(cfg: MjxConfig):
    """The same settings as sim=mjx; on native MuJoCo nthread is the simulation threads."""
    native = native_backend(NativeConfig(nthread=cfg.nthread, max_abs_qvel=cfg.max_abs_qvel))
    if not gpu_visible():
        log.info("sim=auto: no GPU visible to JAX, simulating with native MuJoCo")
        return native
    log.info("sim=auto: JAX sees a GPU, simulating on MJX unless the task's tuning names native MuJoCo faster")
    mjx = mjx_backend(cfg)

    def make(task: Task, num_envs: int) -> Simulator:
        impl = resolve_impl(cfg.impl, cfg.tuning)
        if auto_choice(impl, cfg.tuning) == "mjx":
            return mjx(task, num_envs)
        if (task.name, impl) not in _LOGGED:
            _LOGGED.add((task.name, impl))
            log.info("sim=auto %s: native MuJoCo on CPU threads, not MJX: native measured faster than MJX's %s "
                     "implementation for this task (sim.tuning.native_faster_on; table in docs/benchmarks.md)",
                     task.name, impl)
        return native(task, num_envs)

    return make

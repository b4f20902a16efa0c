"""MJX's two implementations behind its one API (`sim.impl`), chosen once per simulator: MJX's JAX
re-implementation of MuJoCo, and MuJoCo Warp (NVIDIA GPUs, warp-lang installed), which is several times
faster on contact-rich tasks. Everything that differs between them lives here: the model each simulates,
Warp's fixed-size buffers and the slots whose rows overflowed them, the model fields Warp batches, and
whether traced programs can be kept across runs."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import mujoco

from ..errors import ConfigError
from ..tasks.base import Task
from .mjx_setup import import_mjx, leave_out_warp
from .mjx_tuning import tuned_model, warp_buffer

Impl = Literal["auto", "jax", "warp"]  # sim.impl: auto, or one of mjx_tuning.MJX_IMPLS


def resolve_impl(impl: str, tuning: Mapping[str, Any] | None = None) -> str:
    """MJX's implementation for `impl` on this machine; warp asked for where it cannot run is an error.
    auto: the tuning's `impl` where it names one (docs/tasks.md), else Warp where it can run."""
    if _jax_chosen(impl, tuning or {}):
        return "jax"
    import jax

    nvidia = any(d.platform == "gpu" and "nvidia" in d.device_kind.lower() for d in jax.devices())
    if impl == "auto" and not nvidia:
        return "jax"
    import_mjx()
    from mujoco.mjx import warp as mjx_warp

    if mjx_warp.WARP_INSTALLED and nvidia:
        return "warp"
    if impl == "warp":
        raise ConfigError("sim.impl=warp needs an NVIDIA GPU and warp-lang (pip install -e '.[warp]')")
    return "jax"


def _jax_chosen(impl: str, tuning: Mapping[str, Any]) -> bool:
    """sim.impl=jax, or auto where the task's tuning prefers JAX: decided without asking the machine."""
    return impl == "jax" or (impl == "auto" and tuning.get("impl") == "jax")


def settle_for_one_run(sim_cfg: Mapping[str, Any]) -> bool:
    """Called by a process that runs one job (`python -m bayessim_exp` without --multirun) with that job's
    sim config: where its sim.impl and tuning resolve to MJX's JAX implementation, MJX is imported without
    MuJoCo Warp. Processes that may simulate another task later (--multirun, the Python API) keep MJX's own
    import. Returns whether Warp is left out."""
    if "impl" not in sim_cfg or not _jax_chosen(sim_cfg["impl"], sim_cfg.get("tuning") or {}):
        return False
    leave_out_warp()
    return True


class JaxImpl:
    """MJX's JAX implementation: buffers sized fully, every float model leaf batchable."""

    name = "jax"
    keeps_traces = True  # its programs can be exported (trace_cache.py)

    def __init__(self, tuning: Mapping[str, Any]):
        self.tuning = tuning

    def model(self, task: Task) -> mujoco.MjModel:
        return tuned_model(task, self.tuning)

    def put_model(self, mjx: Any, model: mujoco.MjModel) -> Any:
        return mjx.put_model(model, impl=self.name)

    def constants_model(self, mjx: Any, task: Task, nominal: Any) -> Any:
        """The MJX model whose JAX functions compute the derived constants: the simulated one."""
        return nominal

    def data_sizes(self, num_envs: int) -> dict[str, Any]:
        """make_data's keyword arguments for a batch of num_envs."""
        return {}

    def batchable(self, name: str) -> bool:
        return True

    def rows_dropped(self, data: Any, jnp: Any) -> Any:
        """Per slot: constraint rows dropped over the buffer, so the step's physics is wrong (never here)."""
        return jnp.zeros(data.qpos.shape[0], bool)


class WarpImpl(JaxImpl):
    """MuJoCo Warp: contacts of all environments in one buffer, constraint rows in one per environment
    (`contacts_per_env`, `constraints_per_env` in the tuning), some model fields shared by all worlds."""

    name = "warp"
    keeps_traces = False  # MuJoCo Warp's kernels are not exportable

    def model(self, task: Task) -> mujoco.MjModel:
        """The tuning less `min_condim`: Warp has frictionless contacts with elliptic cones."""
        return tuned_model(task, {k: v for k, v in self.tuning.items() if k != "min_condim"})

    def put_model(self, mjx: Any, model: mujoco.MjModel) -> Any:
        return _quiet_solver(mjx.put_model(model, impl=self.name))

    def constants_model(self, mjx: Any, task: Task, nominal: Any) -> Any:
        """MJX's JAX model (the constants do not depend on condim): Warp's has no JAX functions."""
        return JaxImpl(self.tuning).put_model(mjx, JaxImpl(self.tuning).model(task))

    def data_sizes(self, num_envs: int) -> dict[str, Any]:
        return dict(impl=self.name, naconmax=num_envs * warp_buffer(self.tuning, "contacts_per_env"),
                    njmax=warp_buffer(self.tuning, "constraints_per_env"))

    def batchable(self, name: str) -> bool:
        from mujoco.mjx.warp import types as warp_types

        return bool(warp_types._BATCH_DIM["Model"].get(name[4:] if name.startswith("opt.") else name, False))

    def rows_dropped(self, data: Any, jnp: Any) -> Any:
        """MuJoCo Warp drops the constraint rows over `constraints_per_env`: such a slot counts as diverged."""
        return data._impl.nefc > warp_buffer(self.tuning, "constraints_per_env")


def implementation(impl: str, tuning: Mapping[str, Any]) -> JaxImpl:
    """The implementation `impl` (auto, jax, warp) resolves to on this machine for this tuning."""
    return WarpImpl(tuning) if resolve_impl(impl, tuning) == "warp" else JaxImpl(tuning)


def _quiet_solver(mx: Any) -> Any:
    """MuJoCo Warp prints a line per step in which a world reached its solver or line-search
    iteration cap; the tuned models cap iterations on purpose, and the printing cost more than the steps
    (measured on the H100). Overflows of the contact and constraint buffers are still reported."""
    from mujoco.mjx.third_party.mujoco_warp._src.types import OverflowType

    quiet = ~int(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS)
    warp_opt = mx.opt._impl
    return mx.replace(opt=mx.opt.replace(_impl=warp_opt.replace(warn_overflow=warp_opt.warn_overflow & quiet)))

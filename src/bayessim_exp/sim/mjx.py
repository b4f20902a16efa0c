"""GPU backend: N MJX simulations of one task, each with its own parameters.

Two implementations behind MJX's one API (`sim.impl`): MJX's JAX re-implementation of MuJoCo, and MuJoCo
Warp (NVIDIA GPUs, warp-lang installed), which is several times faster on contact-rich tasks.

Per-environment parameters are batched leaves of one `mjx.Model` (`jax.vmap` with in_axes 0 over the
fields the ParamSpec touches, None elsewhere). A reset uploads the parameters [N, D] alone: the fields
(ParamSpec.field_values with jax.numpy) and the constants mj_setConst derives from them that change
within the prior's range (mass, inertia, geometry, ...: mjx_constants, a JAX port) are computed on the
device inside the compiled reset, and replace the old ones in the reset slots. A constant the port does
not cover for a model is computed on the host with `mujoco.batch` and uploaded whole. Observations,
rewards and terminations are the task's own array code, run with xp=jax.numpy inside the compiled step.
Arrays reach torch through DLPack, without copies.

Compilations: one step and one reset per simulator (the pool keeps one per batch size), one fused
rollout per horizon (jax.jit's cache, keyed by the actions' shape); JAX's persistent compilation cache (`cache_dir`) keeps them across processes,
and on MJX's JAX implementation the traced programs too (trace_cache.py), so a later run neither traces nor compiles.
A slot that breaks down is frozen at its last finite state (the fields mjx.step reads), so it neither
spreads NaNs nor keeps the solver iterating, and it stays flagged until its next reset.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.util
import io
import logging
import os
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

# before jax is imported anywhere: JAX and torch share the GPU instead of JAX taking 75 % of it up front
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from mujoco import batch as mjbatch  # noqa: E402

from ..errors import ConfigError  # noqa: E402
from ..registry import register  # noqa: E402
from ..tasks.base import Task, model_bytes  # noqa: E402
from .base import Policy, Simulator, broke_down  # noqa: E402
from .native import NativeConfig, NativeSimulator  # noqa: E402
from .params import ParamSpec, model_field  # noqa: E402
from .trace_cache import ExportedJit, code_fingerprint  # noqa: E402
from .trajectories import Trajectories  # noqa: E402

# fields MJX reads while tracing (collision pairs, sparsity, solver choice): one value for every slot
_STATIC_FIELDS = frozenset({"geom_contype", "geom_conaffinity", "geom_condim", "geom_type", "geom_priority",
                            "opt.iterations", "opt.ls_iterations", "opt.solver", "opt.cone", "opt.integrator",
                            "opt.disableflags", "opt.enableflags", "opt.jacobian"})
# the MjData fields mjx.step reads (MuJoCo's mjSTATE_INTEGRATION); every other field it derives from them
_STEP_INPUTS = ("time", "qpos", "qvel", "act", "history", "qacc_warmstart", "plugin_state", "ctrl", "qfrc_applied",
                "xfrc_applied", "eq_active", "mocap_pos", "mocap_quat", "userdata")
_PROBES = 8  # random parameter sets (besides the bounds) that decide which derived constants vary
log = logging.getLogger(__name__)
_LOGGED: set[tuple] = set()  # (task, implementation) and (task, constants on the host) already reported
_LEAVE_OUT_WARP = False  # set by leave_out_warp: this process simulates on MJX's JAX implementation only


@dataclasses.dataclass
class MjxConfig:
    max_abs_qvel: float  # a joint speed beyond this counts as diverged
    cache_dir: Any  # JAX's persistent compilation cache and the traced programs (str), or None: off
    nthread: int  # CPU threads of the host-side set_const and of the native small batches (0: all)
    native_below: int  # batches smaller than this run on native MuJoCo (the tuned model) on CPU threads
    impl: str  # jax, warp, or auto: warp where warp-lang is installed and the GPU is NVIDIA's

    def validate(self) -> None:
        if self.max_abs_qvel <= 0 or self.nthread < 0 or self.native_below < 0:
            raise ConfigError("max_abs_qvel must be > 0, nthread and native_below >= 0")
        if self.impl not in IMPLS:
            raise ConfigError(f"sim.impl={self.impl!r} not allowed; allowed: {', '.join(IMPLS)}")


IMPLS = ("auto", "jax", "warp")


def resolve_impl(impl: str, task: Task | None = None) -> str:
    """MJX's implementation for `impl` on this machine; warp asked for where it cannot run is an error.
    auto: the task's `mjx_tuning.impl` where it names one (docs/tasks.md), else Warp where it can run."""
    if _jax_chosen(impl, task.cfg.mjx_tuning if task is not None else {}):
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


def _jax_chosen(impl: str, mjx_tuning: Mapping) -> bool:
    """sim.impl=jax, or auto where the task's tuning prefers JAX: decided without asking the machine."""
    return impl == "jax" or (impl == "auto" and mjx_tuning.get("impl") == "jax")


def leave_out_warp(impl: str, mjx_tuning: Mapping) -> bool:
    """Called by a process that runs one job (`python -m bayessim_exp` without --multirun) with that
    job's sim.impl and task tuning: when they resolve to MJX's JAX implementation, MJX is imported
    without MuJoCo Warp, which MJX otherwise imports whenever warp-lang is installed (the larger part of
    importing MJX on the H100 machine, docs/benchmarks.md). Processes that may simulate another task
    later (--multirun, the Python API) keep MJX's own import. Returns whether Warp is left out."""
    global _LEAVE_OUT_WARP
    _LEAVE_OUT_WARP = _jax_chosen(impl, mjx_tuning)
    return _LEAVE_OUT_WARP


def import_mjx() -> Any:
    """mujoco.mjx, imported without MuJoCo Warp where leave_out_warp decided so (and nothing else
    imported warp-lang before)."""
    if "mujoco.mjx" not in sys.modules:
        leave_out = _LEAVE_OUT_WARP and "warp" not in sys.modules and importlib.util.find_spec("warp") is not None
        if leave_out:
            sys.modules["warp"] = None  # type: ignore[assignment]  # `import warp` fails: MJX records Warp as absent
        try:
            # MJX prints every failed import of Warp (as on an install without warp-lang) and Warp its banner
            with contextlib.redirect_stdout(io.StringIO()):
                import mujoco.mjx  # noqa: F401
        finally:
            if leave_out:
                del sys.modules["warp"]
        if leave_out:
            log.info("sim=mjx: MJX imported without MuJoCo Warp (this run simulates with MJX's JAX implementation)")
    from mujoco import mjx

    return mjx


def jax_setup(cache_dir: str | None) -> Any:
    """Import jax with the persistent compilation cache in `cache_dir` (None: off)."""
    import jax

    if cache_dir:
        jax.config.update("jax_compilation_cache_dir", os.path.expanduser(str(cache_dir)))
        # every program, the small ones too: together they took 0.3 s of a warm run to compile again
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    return jax


def gpu_visible() -> bool:
    """JAX sees a GPU (and MJX is installed). Without a GPU driver on the machine JAX is not asked:
    importing it and MJX takes 1.7 s on the 2-core development machine."""
    if not any(os.path.exists(p) for p in ("/dev/nvidiactl", "/dev/kfd", "/proc/driver/nvidia/gpus")):
        return False
    try:
        import jax

        import_mjx()
    except ImportError:
        return False
    return any(d.platform == "gpu" for d in jax.devices())


def _quiet_solver(mx: Any) -> Any:
    """MuJoCo Warp prints a line per step in which a world reached its solver or line-search
    iteration cap; the tuned models cap iterations on purpose, and the printing cost more than the steps
    (measured on the H100). Overflows of the contact and constraint buffers are still reported."""
    from mujoco.mjx.third_party.mujoco_warp._src.types import OverflowType

    quiet = ~int(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS)
    warp_opt = mx.opt._impl
    return mx.replace(opt=mx.opt.replace(_impl=warp_opt.replace(warn_overflow=warp_opt.warn_overflow & quiet)))


def to_torch(x: Any) -> torch.Tensor:
    return torch.from_dlpack(x)


class MjxSimulator(Simulator):
    """`randomize=False` runs every slot on the nominal model and ignores the parameters: what per-slot
    parameters cost is measured against it (benchmarks/sim_throughput.py)."""

    compiles_per_size = True

    def __init__(self, task: Task, num_envs: int, cfg: MjxConfig, randomize: bool = True):
        super().__init__(task, num_envs)
        self.cfg, self.randomize = cfg, randomize
        self.jax = jax = jax_setup(cfg.cache_dir)
        mjx = import_mjx()
        from .mjx_constants import DeviceConstants, host_reasons  # imports MJX and JAX: not on a CPU-only run

        self.jnp, self.mjx = jax.numpy, mjx
        # every input committed to one device: a jitted function sees the same placement on every call
        # (uncommitted first inputs and committed outputs would compile everything twice)
        self._dev = jax.devices()[0]
        m = task.model
        self.impl = resolve_impl(cfg.impl, task)
        self.mj_model = task.tuned_model(self.impl)
        self.nominal = mjx.put_model(self.mj_model, impl=self.impl)
        # MuJoCo Warp keeps contacts of all environments in one buffer, constraint rows per environment
        self._data_sizes = dict(impl="warp", naconmax=num_envs * task.warp_buffer("contacts_per_env"),
                                njmax=task.warp_buffer("constraints_per_env")) if self.impl == "warp" else {}
        # the derived constants are computed by MJX's JAX functions, whichever implementation steps
        self._jax_nominal = self.nominal
        if self.impl == "warp":
            self.nominal = _quiet_solver(self.nominal)
            self._jax_nominal = mjx.put_model(task.mjx_model, impl="jax")  # the constants do not depend on condim
        constants = self._varying_constants() if randomize and task.spec.needs_set_const else []
        if self.impl == "warp":  # MuJoCo Warp keeps some derived constants (dof_M0) one for all worlds
            shared = [n for n in constants if not _warp_batchable(n)]
            if shared:
                log.info("sim.impl=warp: %s stay nominal in every slot (MuJoCo Warp does not batch them)", shared)
            constants = [n for n in constants if n not in shared]
        names = list(task.spec.fields) + constants if randomize else []
        for name in names:
            leaf = model_field(self.nominal, name)
            if not isinstance(leaf, jax.Array) or not jax.numpy.issubdtype(leaf.dtype, jax.numpy.floating):
                raise ConfigError(f"sim=mjx cannot set {name} per simulation: MJX keeps it static")
            if self.impl == "warp" and not _warp_batchable(name):
                raise ConfigError(f"sim.impl=warp cannot set {name} per simulation (MuJoCo Warp shares it "
                                  "between environments); use sim.impl=jax")
        on_host = host_reasons(m, constants)
        if on_host and (task.name, tuple(on_host)) not in _LOGGED:
            _LOGGED.add((task.name, tuple(on_host)))
            log.info("sim=mjx %s: constants computed on the host by mujoco.batch's set_const: %s", task.name,
                     "; ".join(f"{n} ({why})" for n, why in on_host.items()))
        self._setconst = mjbatch.Batch(m, num_envs, nthread=cfg.nthread) if on_host else None
        # host copies [N, ...] of the constants computed there; resets write rows and upload the whole leaf
        self._host = {n: np.repeat(np.asarray(model_field(self.nominal, n))[None], num_envs, 0) for n in on_host}
        self._constants = DeviceConstants(m, mjx.make_data(self._jax_nominal),
                                          [c for c in constants if c not in on_host])
        nominal = {n: np.asarray(model_field(self.nominal, n)) for n in names}
        self.leaves = {n: self._put(np.broadcast_to(v, (num_envs,) + v.shape), v.dtype) for n, v in nominal.items()}
        axes = jax.tree_util.tree_map(lambda _: None, self.nominal)
        self._model_axes = axes.tree_replace({n: 0 for n in names})
        self.data = jax.device_put(jax.jit(self._blank)(), self._dev)
        self.obs = self._put(np.zeros((num_envs, task.obs_dim)), np.float32)
        self.broken = self._put(np.zeros(num_envs, bool))  # since the last reset
        jit = self._jit_maker(names, constants, list(on_host))
        self._reset_fn = jit(self._reset_all, lambda leaves, host, data, obs, broken, *_: (leaves, data, obs, broken))
        self._step_fn = jit(self._control_step, lambda leaves, data, obs, broken, act: (data, obs, broken, 0, 0, 0))
        # one compilation per horizon (the actions' shape)
        self._rollout_fn = jit(self._scan, lambda leaves, data, obs, broken, act: (data, obs, broken, 0, 0, 0, 0, 0))

    def _jit_maker(self, names: list[str], constants: list[str], on_host: list[str]) -> Callable:
        """jax.jit, or where `cache_dir` is set and MJX runs its JAX implementation, a jit whose traced
        program is kept across runs (trace_cache.py; MuJoCo Warp's kernels are not exportable). The key:
        the compiled model and everything else the compiled functions read from this simulator."""
        if self.cfg.cache_dir is None or self.impl != "jax":
            return lambda fn, out_like: self.jax.jit(fn)
        described = repr((type(self.task).__module__, type(self.task).__qualname__, self.task.cfg, self.cfg.max_abs_qvel,
                          self.randomize, names, constants, on_host, self._data_sizes, code_fingerprint()))
        key = hashlib.sha1(model_bytes(self.mj_model) + described.encode()).hexdigest()
        directory = Path(str(self.cfg.cache_dir)).expanduser() / "traces"
        return lambda fn, out_like: ExportedJit(fn, f"{fn.__name__}:{key}", directory, out_like)

    def _put(self, x: Any, dtype: Any = None) -> Any:
        return self.jax.device_put(np.asarray(x, dtype), self._dev)

    # configuration -----------------------------------------------------------------------
    @classmethod
    def check_spec(cls, spec: ParamSpec) -> None:
        mjx = import_mjx()
        known = {f.name for f in dataclasses.fields(mjx.Model)} | {f"opt.{f.name}" for f in dataclasses.fields(mjx.Option)}
        unsupported = [f for f in spec.fields if f not in known or f in _STATIC_FIELDS]
        if unsupported:
            raise ConfigError(f"sim=mjx cannot set {', '.join(unsupported)} per simulation (MJX has no such "
                              "field or reads it while compiling); use sim=native")

    @property
    def device(self) -> torch.device:
        return torch.device("cuda", self._dev.id) if self._dev.platform == "gpu" else torch.device("cpu")

    def _varying_constants(self) -> list[str]:
        """Constants mj_setConst derives that change within the prior's box (batched alongside)."""
        spec, m = self.task.spec, self.task.model
        rng = np.random.default_rng(0)
        probes = np.concatenate([spec.low[None], spec.high[None], rng.uniform(spec.low, spec.high, (_PROBES, spec.dim))])
        probe = mjbatch.Batch(m, len(probes), nthread=1)
        for name, vals in spec.field_values(m, probes).items():
            probe.expand(name)[:] = vals.reshape(probe.expand(name).shape)
        probe.set_const()
        out = []
        for name in mujoco.MjModel._setconst_outputs:
            values = probe.expanded(name)
            if (name in spec.fields or values is None or values.dtype.kind != "f"
                    or not hasattr(self.nominal, name) or np.allclose(values, getattr(m, name)[None], rtol=1e-9, atol=0)):
                continue
            out.append(name)
        return out

    # the compiled pieces -------------------------------------------------------------------
    def _model(self, leaves: dict) -> Any:
        return self.nominal.tree_replace(leaves)

    def _blank(self) -> Any:
        """Data of every slot at the model's defaults (vmapped, so MuJoCo Warp sizes its buffers for all)."""
        return self.jax.vmap(lambda _: self.mjx.make_data(self.mj_model, **self._data_sizes))(
            self.jnp.arange(self.num_envs))

    def _slot_leaves(self, params):
        """Every slot's fields and device-computed constants for parameters [N, D]."""
        fields = self.task.spec.field_values(self.nominal, params, self.jnp)
        fields = {n: self._leaf_layout(n, v) for n, v in fields.items()}
        # full float32 products: a GPU's default TF32 matmuls put Humanoid's actuator_acc0 off by 3 % (H100)
        with self.jax.default_matmul_precision("float32"):
            constants = self.jax.vmap(lambda f: self._constants(self._jax_nominal.tree_replace(f)))(fields)
        return fields | {n: self._leaf_layout(n, v) for n, v in constants.items()}

    def _leaf_layout(self, name: str, values: Any) -> Any:
        """Values [k, ...] of a model field in the simulated model's layout (MuJoCo Warp keeps geom_aabb as
        [2, 3] per geom where MuJoCo and MJX's JAX implementation have 6)."""
        return values.reshape(values.shape[:1] + model_field(self.nominal, name).shape)

    def _reset_all(self, leaves, host_leaves, data, obs, broken, mask, params, state):
        """New leaves (from `params`), fresh data with `state` and a forward pass in the slots of `mask`; the
        others keep theirs. Without randomization `params` is None and the leaves stay."""
        jax, jnp = self.jax, self.jnp
        if params is not None:
            new = self._slot_leaves(params)
            leaves = leaves | _where(jnp, mask, new, {n: leaves[n] for n in new}) | host_leaves
        fresh = self._blank()
        fresh = fresh.replace(**{k: jnp.asarray(v, getattr(fresh, k).dtype).reshape(getattr(fresh, k).shape)
                                 for k, v in state.items()})
        fresh = jax.vmap(self.mjx.forward, in_axes=(self._model_axes, 0))(self._model(leaves), fresh)
        # Data.where merges only the per-slot fields (MuJoCo Warp's contact buffer is shared)
        data = jax.vmap(lambda d, f, m: d.where(m, f))(data, fresh, mask)
        new_obs = jnp.asarray(self.task.observe(data, xp=jnp), jnp.float32)
        obs = jnp.where(mask[:, None], new_obs, obs)
        return leaves, data, obs, broken & ~mask

    def _control_step(self, leaves, data, obs, broken, actions):
        jax, jnp = self.jax, self.jnp
        mx = self._model(leaves)
        before = data
        data = data.replace(ctrl=jnp.asarray(self.task.ctrl(actions, xp=jnp), data.ctrl.dtype))
        step = jax.vmap(self.mjx.step, in_axes=(self._model_axes, 0))

        def substep(_, carry):
            d, overflowed = carry
            d = step(mx, d)
            return d, overflowed | self._rows_dropped(d)

        data, overflowed = jax.lax.fori_loop(0, self.task.frame_skip, substep,
                                             (data, jnp.zeros(obs.shape[0], bool)))
        now_broken = broke_down(data.qpos, data.qvel, self.cfg.max_abs_qvel, xp=jnp) | overflowed
        held = now_broken | broken
        # frozen at the last finite state, so it never poisons the batch; only what mjx.step reads is
        # restored (the derived fields are recomputed from it), a fraction of the memory traffic
        data = data.replace(**_where(jnp, held, {f: getattr(before, f) for f in _STEP_INPUTS},
                                     {f: getattr(data, f) for f in _STEP_INPUTS}))
        new_obs = jnp.where(held[:, None], obs, jnp.asarray(self.task.observe(data, xp=jnp), jnp.float32))
        reward = jnp.asarray(self.task.reward(obs, actions, new_obs, xp=jnp), jnp.float32)
        terminated = jnp.asarray(self.task.terminated(new_obs, xp=jnp), bool)
        return data, new_obs, held, reward, terminated, now_broken

    def _rows_dropped(self, data):
        """Per slot: MuJoCo Warp dropped constraint rows over its buffer (`constraints_per_env`), so the
        step's physics is wrong; the slot counts as diverged. MJX's JAX implementation sizes them fully."""
        if self.impl != "warp":
            return self.jnp.zeros(data.qpos.shape[0], bool)
        return data._impl.nefc > self._data_sizes["njmax"]

    # the protocol ------------------------------------------------------------------------------
    def _reset(self, params: torch.Tensor, ids: torch.Tensor, state: dict[str, np.ndarray]) -> torch.Tensor:
        ids_np = ids.numpy()
        spec, slot_params = self.task.spec, None
        if self.randomize:  # the slots not reset get the nominal parameters: computed, then discarded
            slot_params = np.tile(spec.nominal.astype(np.float32), (self.num_envs, 1))
            slot_params[ids_np] = params.numpy()
            slot_params = self._put(slot_params)
        if self._setconst is not None:
            for name, vals in spec.field_values(self.task.model, params.numpy()).items():
                target = self._setconst.expand(name)
                target[ids_np] = vals.reshape((len(ids_np),) + target.shape[1:])
            self._setconst.set_const(ids_np)
            for name, rows in self._host.items():  # batch.set_const leaves a constant shared while no slot changed it
                derived = self._setconst.expanded(name)
                rows[ids_np] = self._leaf_layout(name, getattr(self.task.model, name)[None] if derived is None
                                                 else derived[ids_np])
        host_leaves = {n: self._put(v, self.leaves[n].dtype) for n, v in self._host.items()}
        mask = np.zeros(self.num_envs, bool)
        mask[ids_np] = True
        full_state = {}
        for field, v in state.items():
            current = getattr(self.data, field)
            arr = np.zeros(current.shape, current.dtype)
            arr[ids_np] = np.asarray(v).reshape((len(ids_np),) + current.shape[1:])
            full_state[field] = self._put(arr)
        self.leaves, self.data, self.obs, self.broken = self._reset_fn(
            self.leaves, host_leaves, self.data, self.obs, self.broken, self._put(mask), slot_params, full_state)
        return to_torch(self.obs)[ids.to(self.device)]

    def _step(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        act = self.jnp.from_dlpack(actions.detach().float().to(self.device).contiguous())
        self.data, self.obs, self.broken, reward, terminated, broken = self._step_fn(
            self.leaves, self.data, self.obs, self.broken, act)
        return to_torch(self.obs), to_torch(reward), to_torch(terminated), to_torch(broken)

    # the fused rollout: same Trajectories as Simulator.rollout, one compiled loop ------------------
    def rollout(self, params, policy: Policy, horizon: int, seed: int = 0, progress: bool = False,
                state: dict[str, np.ndarray] | None = None) -> Trajectories:
        """Simulator.rollout in one compiled `lax.scan` when the policy is open-loop (its actions do not
        read the observations: `open_loop_actions`); otherwise the generic step-by-step loop."""
        if not hasattr(policy, "open_loop_actions"):
            return super().rollout(params, policy, horizon, seed, progress, state)
        self.reset(params, None, seed, state)
        actions = policy.open_loop_actions(self.num_envs, horizon).to(self.device, torch.float32).clamp(-1.0, 1.0)
        out = self._rollout_fn(self.leaves, self.data, self.obs, self.broken,
                                      self.jnp.from_dlpack(actions.transpose(0, 1).contiguous()))
        self.data, self.obs, self.broken, states, acts, rewards, valid, diverged = out
        self.elapsed += horizon
        self.diverged |= to_torch(diverged).cpu()
        return Trajectories(states=to_torch(states), actions=to_torch(acts), rewards=to_torch(rewards),
                            valid=to_torch(valid), diverged=to_torch(diverged), dt=self.task.cfg.control_dt)

    def _scan(self, leaves, data, obs, broken, actions):
        """actions [T, N, A]; the bookkeeping of Simulator.step and Simulator.rollout, step by step."""
        jax, jnp = self.jax, self.jnp

        def body(carry, act):
            data, obs, held, alive, diverged, last = carry
            data, obs, held, reward, terminated, now_broken = self._control_step(leaves, data, obs, held, act)
            diverged = diverged | now_broken
            terminated = terminated & ~diverged
            alive = alive & ~diverged
            out = (jnp.where(alive[:, None], obs, last), jnp.where(alive[:, None], act, 0.0),
                   jnp.where(alive, reward, 0.0), alive)
            state = jnp.where(alive[:, None], obs, last)
            return (data, obs, held, alive & ~terminated, diverged, state), out

        n = obs.shape[0]
        init = (data, obs, broken, jnp.ones(n, bool), jnp.zeros(n, bool), obs)
        (data, obs, broken, _, diverged, _), (states, acts, rewards, valid) = jax.lax.scan(body, init, actions)
        states = jnp.concatenate([init[-1][:, None], states.transpose(1, 0, 2)], 1)
        return (data, obs, broken, states, acts.transpose(1, 0, 2), rewards.T, valid.T, diverged)


def _warp_batchable(name: str) -> bool:
    from mujoco.mjx.warp import types as warp_types

    return bool(warp_types._BATCH_DIM["Model"].get(name[4:] if name.startswith("opt.") else name, False))


def _where(jnp: Any, mask: Any, a: Any, b: Any) -> Any:
    """Per slot: a where mask, else b, over every leaf of two batched pytrees."""
    import jax

    return jax.tree_util.tree_map(lambda x, y: jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)), x, y), a, b)


@register("sim", "mjx", MjxConfig)
def mjx_backend(cfg: MjxConfig):
    """The sim group builds a factory: (task, num_envs) -> simulator. A small batch (the real stage's few
    trajectories, the model checks' replays) takes less time on CPU threads than compiling MJX for its
    size would; it simulates the same tuned model there."""
    native = NativeConfig(nthread=cfg.nthread, max_abs_qvel=cfg.max_abs_qvel)
    resolve_impl(cfg.impl)  # sim.impl=warp where it cannot run fails here, before any stage

    def make(task: Task, num_envs: int) -> Simulator:
        impl = resolve_impl(cfg.impl, task)
        if (task.name, impl) not in _LOGGED:
            _LOGGED.add((task.name, impl))
            log.info("sim=mjx %s: MJX implementation %s (sim.impl=%s)", task.name, impl, cfg.impl)
        if num_envs < cfg.native_below:
            return NativeSimulator(task, num_envs, native, model=task.tuned_model(impl))
        return MjxSimulator(task, num_envs, cfg)

    return make

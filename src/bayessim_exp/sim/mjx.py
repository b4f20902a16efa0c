"""GPU backend: N MJX simulations of one task, each with its own parameters.

MJX's implementation (JAX or MuJoCo Warp) is chosen once per simulator (mjx_impl.py), the task's model
tuned for it (mjx_tuning.py, `sim.tuning`).

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

import dataclasses
import functools
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch
from mujoco import batch as mjbatch

from ..errors import ConfigError
from ..policies import Policy
from ..tasks.base import Task
from ..tasks.params import ParamSpec, model_field
from .base import Simulator, broke_down
from .mjx_impl import Impl, implementation, resolve_impl
from .mjx_setup import import_mjx, jax_setup
from .mjx_tuning import check_tuning, native_measured_faster
from .native import NativeConfig, NativeSimulator, simulation_threads
from .trace_cache import ExportedJit, code_fingerprint, program_key
from .trajectories import Trajectories

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


@dataclasses.dataclass
class MjxConfig:
    max_abs_qvel: float  # a joint speed beyond this counts as diverged
    cache_dir: Any  # JAX's persistent compilation cache and the traced programs (str), or None: off
    nthread: int  # CPU threads of the host-side set_const and of the native small batches (0: the process's CPUs)
    native_below: int  # batches smaller than this run on native MuJoCo (the tuned model) on CPU threads
    impl: Impl  # auto: warp where warp-lang is installed and the GPU is NVIDIA's
    tuning: dict[str, Any]  # the task's model tuned for MJX (mjx_tuning.py; conf/mjx_tuning/<task>.yaml)

    def validate(self) -> None:
        if self.max_abs_qvel <= 0 or self.nthread < 0 or self.native_below < 0:
            raise ConfigError("max_abs_qvel must be > 0, nthread and native_below >= 0")
        check_tuning(self.tuning)

    def runs_natively(self, num_envs: int) -> bool:
        """A batch this small simulates on native MuJoCo: both the sim group's factory and the padding read it."""
        return num_envs < self.native_below


def to_torch(x: Any) -> torch.Tensor:
    return torch.from_dlpack(x)


class MjxSimulator(Simulator):
    """`randomize=False` runs every slot on the nominal model and ignores the parameters: what per-slot
    parameters cost is measured against it (benchmarks/sim_throughput.py)."""

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
        self.impl = implementation(cfg.impl, cfg.tuning)
        self.mj_model = self.impl.model(task)
        self.nominal = self.impl.put_model(mjx, self.mj_model)
        self._data_sizes = self.impl.data_sizes(num_envs)
        # the derived constants are computed by MJX's JAX functions, whichever implementation steps
        self._jax_nominal = self.impl.constants_model(mjx, task, self.nominal)
        constants = self._varying_constants() if randomize and task.spec.needs_set_const else []
        # MuJoCo Warp keeps some derived constants (dof_M0) one for all worlds
        shared = [n for n in constants if not self.impl.batchable(n)]
        if shared:
            log.info("sim.impl=%s: %s stay nominal in every slot (MuJoCo Warp does not batch them)", self.impl.name,
                     shared)
        constants = [n for n in constants if n not in shared]
        names = list(task.spec.fields) + constants if randomize else []
        for name in names:
            leaf = model_field(self.nominal, name)
            if not isinstance(leaf, jax.Array) or not jax.numpy.issubdtype(leaf.dtype, jax.numpy.floating):
                raise ConfigError(f"sim=mjx cannot set {name} per simulation: MJX keeps it static")
            if not self.impl.batchable(name):
                raise ConfigError(f"sim.impl={self.impl.name} cannot set {name} per simulation (MuJoCo Warp shares "
                                  "it between environments); use sim.impl=jax")
        on_host = host_reasons(m, constants)
        if on_host and (task.name, tuple(on_host)) not in _LOGGED:
            _LOGGED.add((task.name, tuple(on_host)))
            log.info("sim=mjx %s: constants computed on the host by mujoco.batch's set_const: %s", task.name,
                     "; ".join(f"{n} ({why})" for n, why in on_host.items()))
        self._setconst = mjbatch.Batch(m, num_envs, nthread=simulation_threads(cfg.nthread)) if on_host else None
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
        self._closed_loops: dict[Callable, Callable] = {}  # jitted per policy function

    def pads(self, num_rows: int) -> bool:
        """A batch below native_below runs on native MuJoCo (mjx_backend) even after a chunk-sized simulator exists:
        padded, a model check's few hundred simulations would cost a whole chunk's rollout."""
        return not self.cfg.runs_natively(num_rows)

    def _jit_maker(self, names: list[str], constants: list[str], on_host: list[str]) -> Callable:
        """jax.jit, or where `cache_dir` is set and MJX runs its JAX implementation, a jit whose traced
        program is kept across runs (trace_cache.py; MuJoCo Warp's kernels are not exportable). The key:
        the compiled model and everything else the compiled functions read from this simulator."""
        if self.cfg.cache_dir is None or not self.impl.keeps_traces:
            return lambda fn, out_like: self.jax.jit(fn)
        described = repr((type(self.task).__module__, type(self.task).__qualname__, self.task.cfg, self.cfg.max_abs_qvel,
                          self.cfg.tuning, self.randomize, names, constants, on_host, self._data_sizes,
                          code_fingerprint()))
        key = program_key(self.mj_model, described)
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
            return d, overflowed | self.impl.rows_dropped(d, jnp)

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
        if policy.open_loop_actions is None:
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


    # a closed loop with resets: a JAX policy inside the compiled rollout (PPO's collection) -----------------
    @property
    def closes_loops(self) -> bool:
        """Whether `closed_loop` can run: every reset is computed on the device (no constant from the host's
        set_const, which a compiled loop cannot call)."""
        return self._setconst is None

    def closed_loop(self, policy_fn: Callable, policy_args: Any, noise: torch.Tensor, reset_params: torch.Tensor,
                    reset_states: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        """T control steps of every slot in one compiled `lax.scan`, actions from `policy_fn(policy_args, obs,
        noise_t) -> (actions [N, A], extras {name: [N, ...]})` evaluated inside it, and each slot that ends an
        episode reset at once to its row of that step's draws (reset_params [T, N, D], reset_states {field:
        [T, N, ...]}): the step-by-step `step` with a reset after it, as rl/env.py's environment does.

        Returns [T, N, ...] tensors on the device: observation (before the step), action (as the policy gave
        it; the simulator clamps), the extras, and the step's next_observation (before any reset), reward,
        terminated (diverged slots included) and truncated (episode length reached, not terminated)."""
        if not self.closes_loops:
            raise ValueError(f"{self.task.name}: constants computed on the host at every reset; no closed loop on MJX")
        run = self._closed_loops.get(policy_fn)
        if run is None:
            run = self._closed_loops[policy_fn] = self.jax.jit(functools.partial(self._loop, policy_fn))
        params = self._put(reset_params.numpy(), np.float32) if self.randomize else None
        states = {k: self._put(v, getattr(self.data, k).dtype) for k, v in reset_states.items()}
        elapsed = self._put(self.elapsed.numpy(), np.int32)
        (self.leaves, self.data, self.obs, self.broken, elapsed), out = run(
            self.leaves, self.data, self.obs, self.broken, elapsed, policy_args,
            self.jnp.from_dlpack(noise.detach().float().contiguous()), params, states)
        self.elapsed = to_torch(elapsed).cpu().long()
        self.diverged = to_torch(self.broken).cpu().clone()
        return {k: to_torch(v) for k, v in out.items()}

    def _loop(self, policy_fn, leaves, data, obs, broken, elapsed, policy_args, noise, params, states):
        jax, jnp = self.jax, self.jnp
        limit = self.task.cfg.episode_length

        def body(carry, xs):
            leaves, data, obs, broken, elapsed = carry
            noise_t, params_t, states_t = xs
            actions, extras = policy_fn(policy_args, obs, noise_t)
            data, next_obs, held, reward, terminated, _ = self._control_step(
                leaves, data, obs, broken, jnp.clip(actions, -1.0, 1.0))
            elapsed = elapsed + 1
            terminated = terminated | held  # Simulator.step's bookkeeping, then the environment's
            truncated = (elapsed >= limit) & ~terminated
            done = terminated | truncated
            # the reset's constants cost about a physics step: computed only where some slot ends its episode
            leaves, data, obs, broken = jax.lax.cond(
                done.any(), lambda a: self._reset_all(*a, done, params_t, states_t),
                lambda a: a[:1] + a[2:], (leaves, {}, data, next_obs, held))
            out = {"observation": carry[2], "action": actions, "next_observation": next_obs,
                   "reward": jnp.where(held, 0.0, reward), "terminated": terminated, "truncated": truncated} | extras
            return (leaves, data, obs, broken, jnp.where(done, 0, elapsed)), out

        return jax.lax.scan(body, (leaves, data, obs, broken, elapsed), (noise, params, states))


def _where(jnp: Any, mask: Any, a: Any, b: Any) -> Any:
    """Per slot: a where mask, else b, over every leaf of two batched pytrees."""
    import jax

    return jax.tree_util.tree_map(lambda x, y: jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)), x, y), a, b)


def mjx_backend(cfg: MjxConfig):
    """The sim group builds a factory: (task, num_envs) -> simulator. A small batch (the real stage's few
    trajectories, the model checks' replays) takes less time on CPU threads than compiling MJX for its
    size would; it simulates the same tuned model there."""
    native = NativeConfig(nthread=cfg.nthread, max_abs_qvel=cfg.max_abs_qvel)
    resolve_impl(cfg.impl)  # sim.impl=warp where it cannot run fails here, before any stage

    def make(task: Task, num_envs: int) -> Simulator:
        impl = implementation(cfg.impl, cfg.tuning)
        if (task.name, impl.name) not in _LOGGED:
            _LOGGED.add((task.name, impl.name))
            log.info("sim=mjx %s: MJX implementation %s (sim.impl=%s)", task.name, impl.name, cfg.impl)
            if native_measured_faster(impl.name, cfg.tuning):  # asked for MJX: it simulates, but slower
                log.warning("sim=mjx %s: native MuJoCo on this machine's CPUs measured faster than MJX's %s "
                            "implementation for this task (sim.tuning.native_faster_on; table in "
                            "docs/benchmarks.md); sim=auto would simulate natively", task.name, impl.name)
        if cfg.runs_natively(num_envs):
            return NativeSimulator(task, num_envs, native, model=impl.model(task))
        return MjxSimulator(task, num_envs, cfg)

    return make

"""A task's tuning for MJX (`sim.tuning`, conf/mjx_tuning/<task>.yaml; docs/tasks.md): what makes its model
fast on the GPU backend without changing what it simulates much. The native backend simulates the MJCF
as written.

The keys, the model's first (MODEL_TUNING): solver iterations and line-search iterations (MjOption), MJX's
contact caps (custom numerics it reads: contacts per geom pair, geom pairs per collision function), the
smallest geom condim (MJX's JAX implementation has no frictionless contacts with elliptic cones); then
MuJoCo Warp's buffers per environment (contacts, constraint rows; what overflows them is dropped),
`impl: jax` where MJX's JAX implementation is the faster one for the task (sim.impl=auto takes it), and
`native_faster_on`: the implementations on which native MuJoCo on the machine's CPUs measured faster for the
task (docs/benchmarks.md; sim=auto simulates natively there, sim/auto.py).
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from typing import Any

import mujoco

from ..errors import ConfigError
from ..tasks.base import Task

MODEL_TUNING = ("iterations", "ls_iterations", "max_contact_points", "max_geom_pairs", "min_condim")
# MuJoCo Warp's own default sizes for models without height fields or flexes (mujoco_warp io.py)
WARP_BUFFERS = {"contacts_per_env": 48, "constraints_per_env": 64}
MJX_IMPLS = ("jax", "warp")  # MJX's implementations (mjx_impl.py), as sim.impl and the tuning name them
TUNING_KEYS = (*MODEL_TUNING, *WARP_BUFFERS, "impl", "native_faster_on")
# compiled tuned models per task and tuning: every simulator size and the small native batches share one
_TUNED: weakref.WeakKeyDictionary[Task, dict[tuple, mujoco.MjModel]] = weakref.WeakKeyDictionary()


def check_tuning(tuning: Mapping[str, Any]) -> None:
    unknown = set(tuning) - set(TUNING_KEYS)
    if unknown:
        raise ConfigError(f"sim.tuning: unknown keys {sorted(unknown)}; allowed: {', '.join(TUNING_KEYS)}")
    if tuning.get("impl", "jax") != "jax":
        raise ConfigError(f"sim.tuning.impl={tuning['impl']!r}: only 'jax' can be preferred (sim.impl=auto "
                          "takes MuJoCo Warp wherever it runs otherwise)")
    small = [k for k in WARP_BUFFERS if k in tuning and int(tuning[k]) < 1]
    if small:
        raise ConfigError(f"sim.tuning: {', '.join(small)} must be >= 1")
    slower = tuning.get("native_faster_on", [])
    if isinstance(slower, str) or not isinstance(slower, Sequence) or any(v not in MJX_IMPLS for v in slower):
        raise ConfigError(f"sim.tuning.native_faster_on={slower!r}: a list of MJX implementations from "
                          f"{', '.join(MJX_IMPLS)} (e.g. [jax])")


def native_measured_faster(impl: str, tuning: Mapping[str, Any]) -> bool:
    """Native MuJoCo on the machine's CPUs measured faster for the task than MJX's implementation `impl`."""
    return impl in tuning.get("native_faster_on", [])


def warp_buffer(tuning: Mapping[str, Any], key: str) -> int:
    return int(tuning.get(key, WARP_BUFFERS[key]))


def tuned_model(task: Task, tuning: Mapping[str, Any]) -> mujoco.MjModel:
    """The task's model with the tuning's model settings; the task's own model where it sets none."""
    settings = tuple(sorted((k, v) for k, v in tuning.items() if k in MODEL_TUNING))
    if not settings:
        return task.model
    models = _TUNED.setdefault(task, {})
    if settings not in models:
        models[settings] = _compile(task, dict(settings))
    return models[settings]


def _compile(task: Task, tuning: dict[str, Any]) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(task.model_path))
    for key in ("iterations", "ls_iterations"):
        if key in tuning:
            setattr(spec.option, key, int(tuning[key]))
    for geom in spec.geoms if "min_condim" in tuning else ():
        geom.condim = max(geom.condim, int(tuning["min_condim"]))
    for key in ("max_contact_points", "max_geom_pairs"):
        if key in tuning:
            spec.add_numeric(name=key, data=[float(tuning[key])])
    return spec.compile()

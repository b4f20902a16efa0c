"""Importing JAX and MJX for the GPU backend: GPU memory shared with torch, JAX's persistent compilation
cache, MJX imported without MuJoCo Warp where a run will not use it, and whether JAX sees a GPU at all."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import logging
import os
import sys
from typing import Any

# before jax is imported anywhere: JAX and torch share the GPU instead of JAX taking 75 % of it up front
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

log = logging.getLogger(__name__)
_WARP_LEFT_OUT = False  # set by leave_out_warp: this process simulates on MJX's JAX implementation only


def leave_out_warp() -> None:
    """MJX is imported without MuJoCo Warp, which MJX otherwise imports whenever warp-lang is installed (the
    larger part of importing MJX on the H100 machine, docs/benchmarks.md). Only for a process that will
    never simulate with Warp (mjx_impl.settle_for_one_run decides)."""
    global _WARP_LEFT_OUT
    _WARP_LEFT_OUT = True


def import_mjx() -> Any:
    """mujoco.mjx, imported without MuJoCo Warp where leave_out_warp asked so (and nothing else imported
    warp-lang before)."""
    if "mujoco.mjx" not in sys.modules:
        leave_out = _WARP_LEFT_OUT and "warp" not in sys.modules and importlib.util.find_spec("warp") is not None
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

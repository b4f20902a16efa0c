"""The composed config against this machine, checked when a run is built, before anything is simulated.

What this machine cannot run is refused with one ConfigError naming the fix: a torch device torch does not see
(device=cuda on a CPU-only torch), sim=mjx without JAX and MJX installed. Where the program can choose for the
user it does, and says so once per process: summarizer=signatory's pysiglib backend on a GPU with a pysiglib
built without CUDA becomes the plain-torch backend (the same signatures, on the GPU: summarizers/tensor_algebra.py).

Checked where the options themselves know more, also before any simulation: sim.impl=warp without an NVIDIA GPU
or warp-lang (sim/mjx.py's build), real-data files that are missing or unreadable (their readers: real.py,
recorded/).
"""

from __future__ import annotations

import copy
import importlib.util
import logging
import os

import torch
from omegaconf import DictConfig

from .errors import ConfigError
from .run_config import RunConfig

log = logging.getLogger(__name__)
_SAID: set[str] = set()  # the choices already logged by this process


def usable_cpus() -> int:
    """The CPUs this process may run on: its affinity (a Slurm job's share, a pinned test worker's), not the
    machine's count (macOS and Windows have no affinity call: every CPU there)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def fit_to_machine(cfg: DictConfig, rc: RunConfig) -> DictConfig:
    """`cfg` as this machine runs it: a copy where a choice was made for the user, `cfg` itself otherwise."""
    device = check_device(rc.device)
    check_simulator(cfg.sim)
    return signature_backend(cfg, device)


def check_device(name: str) -> torch.device:
    device = torch.device(name)  # a name torch cannot parse: run_config refused it already
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError(f"device={name}: this torch ({torch.__version__}) sees no CUDA GPU; run with device=cpu")
        count = torch.cuda.device_count()
        if device.index is not None and device.index >= count:
            raise ConfigError(f"device={name}: torch sees {count} CUDA GPU(s), cuda:0 to cuda:{count - 1}; "
                              "run with device=cuda")
    elif device.type == "mps" and not torch.backends.mps.is_available():
        raise ConfigError(f"device={name}: torch sees no Apple GPU here; run with device=cpu")
    elif device.type not in ("cpu", "cuda", "mps"):
        raise ConfigError(f"device={name}: runs use device=cpu, device=cuda or device=mps")
    return device


def check_simulator(sim: DictConfig) -> None:
    """sim=mjx needs JAX and MJX (sim=auto without them simulates natively)."""
    if sim.get("name") == "mjx" and not all(_installed(m) for m in ("jax", "mujoco.mjx")):
        raise ConfigError("sim=mjx needs JAX and MJX, which are not installed: pip install -e '.[gpu]' (NVIDIA GPU) "
                          "or -e '.[mjx]' (CPU), or run with sim=native")


def signature_backend(cfg: DictConfig, device: torch.device) -> DictConfig:
    """summarizer=signatory with backend=pysiglib on a GPU needs pysiglib built with CUDA; without it, the torch
    backend (same features, any device) is chosen and logged once."""
    s = cfg.summarizer
    if s.get("name") != "signatory" or s.get("backend") != "pysiglib" or device.type != "cuda":
        return cfg
    import pysiglib

    if pysiglib.BUILT_WITH_CUDA:
        return cfg
    if "signature_backend" not in _SAID:
        _SAID.add("signature_backend")
        log.warning("device=%s: this pysiglib was built without CUDA, so summarizer=signatory takes "
                    "summarizer.backend=torch (the same signatures, computed on the GPU)", device)
    cfg = copy.deepcopy(cfg)
    cfg.summarizer.backend = "torch"
    return cfg


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package missing
        return False

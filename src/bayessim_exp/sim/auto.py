"""sim=auto: MJX when JAX sees a GPU, native MuJoCo on CPU threads otherwise."""

from __future__ import annotations

import logging

from .mjx import MjxConfig, mjx_backend
from .mjx_setup import gpu_visible
from .native import NativeConfig, native_backend

log = logging.getLogger(__name__)


def auto_backend(cfg: MjxConfig):
    """The same settings as sim=mjx; on native MuJoCo nthread is the simulation threads."""
    if gpu_visible():
        log.info("sim=auto: JAX sees a GPU, simulating on MJX")
        return mjx_backend(cfg)
    log.info("sim=auto: no GPU visible to JAX, simulating with native MuJoCo")
    return native_backend(NativeConfig(nthread=cfg.nthread, max_abs_qvel=cfg.max_abs_qvel))

"""sim=auto: MJX when JAX sees a GPU, native MuJoCo on CPU threads otherwise."""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

from ..errors import ConfigError
from ..registry import register
from .mjx import MjxConfig, gpu_visible, mjx_backend
from .native import NativeConfig, native_backend

log = logging.getLogger(__name__)


@dataclasses.dataclass
class AutoConfig:
    nthread: int  # native: simulation threads; mjx: threads of the host-side set_const (0: all CPUs)
    max_abs_qvel: float  # a joint speed beyond this counts as diverged
    cache_dir: Any  # mjx: JAX's persistent compilation cache, or None: off
    native_below: int  # mjx: batches smaller than this run on native MuJoCo

    def validate(self) -> None:
        if self.nthread < 0 or self.max_abs_qvel <= 0 or self.native_below < 0:
            raise ConfigError("nthread and native_below must be >= 0 and max_abs_qvel > 0")


@register("sim", "auto", AutoConfig)
def auto_backend(cfg: AutoConfig):
    if gpu_visible():
        log.info("sim=auto: JAX sees a GPU, simulating on MJX")
        return mjx_backend(MjxConfig(max_abs_qvel=cfg.max_abs_qvel, cache_dir=cfg.cache_dir, nthread=cfg.nthread,
                                     native_below=cfg.native_below))
    log.info("sim=auto: no GPU visible to JAX, simulating with native MuJoCo")
    return native_backend(NativeConfig(nthread=cfg.nthread, max_abs_qvel=cfg.max_abs_qvel))

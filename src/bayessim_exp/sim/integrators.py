"""Integrators as a nuisance of the simulations: slots that alternate between MuJoCo integrators.

A real system's dynamics are continuous; our simulator integrates them at the model's time step, and that
error is part of the model error. Simulations whose slots alternate between the model's own integrator and
a higher-order one (RK4, close to the continuous dynamics at the same step) show the posterior model which
summary features the integration moves, so q reads the parameters from the others instead of taking the
integration error for a parameter shift (docs/statistics.md, 'Integrators as a nuisance').
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import mujoco
from omegaconf import DictConfig

from ..errors import ConfigError

log = logging.getLogger(__name__)
_SAID: set[str] = set()  # the messages for_run has logged in this process

MODEL = "model"  # the task's MJCF's own integrator
MJCF_NAMES = ("Euler", "RK4", "implicit", "implicitfast")  # as the MJCF's <option integrator=...> spells them
NAMES = (MODEL, *MJCF_NAMES)
AUTO = "auto"
RECORDED_DATA = (MODEL, "RK4")  # auto's choice for data our simulator did not produce


def check_names(names: str | Sequence[str]) -> None:
    """ConfigError unless `names` is "auto" or a non-empty list of NAMES."""
    if names == AUTO:
        return
    if isinstance(names, str) or not names or any(n not in NAMES for n in names):
        raise ConfigError(f"integrators={names!r}: give auto or a list of {', '.join(NAMES)} "
                          f"(e.g. [{', '.join(RECORDED_DATA)}])")


def resolve(names: str | Sequence[str], surrogate: bool) -> tuple[str, ...]:
    """The integrators a run's simulations alternate between: auto is the model's own alone where the real data
    come from this simulator (a surrogate), RECORDED_DATA otherwise."""
    if names == AUTO:
        return (MODEL,) if surrogate else RECORDED_DATA
    return tuple(names)


def codes(names: Sequence[str], model: mujoco.MjModel) -> list[int]:
    """mujoco.mjtIntegrator values of `names`, MODEL read from `model`."""
    members = mujoco.mjtIntegrator.__members__
    return [int(model.opt.integrator) if n == MODEL else int(members[f"mjINT_{n.upper()}"]) for n in names]


def varies(names: Sequence[str]) -> bool:
    """Whether the slots would differ from the model's own integrator anywhere."""
    return any(n != MODEL for n in names)


def for_run(cfg: DictConfig) -> tuple[str, ...]:
    """The integrators a run's method simulates with, alternating slot by slot: () for a method without
    `integrators` (sysid and simopt fit replays row by row); auto is the model's own where the real data are our own
    simulator's (real=surrogate) and RECORDED_DATA otherwise, and the model's own on MJX, which compiles one
    integrator for every simulation (said once); a list that alternates on MJX is refused."""
    names = cfg.method.get("integrators")
    if names is None:
        return ()
    check_names(names)
    resolved = resolve(names, surrogate=cfg.real.get("name") == "surrogate")
    if not varies(resolved):
        return resolved
    from .auto import simulates_on_mjx  # the backends import this module

    if simulates_on_mjx(cfg.sim):
        if names != AUTO:
            raise ConfigError(f"method.integrators={list(names)}: MJX compiles one integrator for every simulation; "
                              "run with sim=native, or method.integrators=[model]")
        _say_once(logging.WARNING, "sim=%s simulates on MJX, which compiles one integrator: the "
                  "simulations do not alternate %s as native MuJoCo's do for recorded data (sim=native; "
                  "docs/statistics.md, 'Integrators as a nuisance')", cfg.sim.name, list(resolved))
        return (MODEL,)
    _say_once(logging.INFO, "the simulations alternate the integrators %s slot by slot "
              "(method.integrators=%s)", list(resolved), names if names == AUTO else list(names))
    return resolved


def _say_once(level: int, message: str, *args) -> None:
    if message not in _SAID:
        _SAID.add(message)
        log.log(level, message, *args)

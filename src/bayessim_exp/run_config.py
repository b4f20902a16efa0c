"""The top-level keys of a run that are not component groups: their types (defaults: conf/config.yaml)."""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from . import registry
from .errors import ConfigError


@dataclasses.dataclass
class CollectConfig:
    trajectories: int  # simulated trajectories per round
    horizon: int  # control steps per trajectory
    chunk: int  # environments simulated at once
    keep_trajectories: bool  # keep raw simulated trajectories after summarizing


@dataclasses.dataclass
class DiagnosticsConfig:
    held_out_fraction: float  # of each round's simulations, kept out of training for the coverage check
    coverage_samples: int  # posterior draws per held-out simulation
    levels: list[float]
    predictive_sims: int  # simulations at posterior and at prior draws for the predictive check (0: off)
    replay_sims: int  # posterior and prior draws replayed per real trajectory (0: off)
    combination_sets: int  # simulated sets of as many trajectories as real ones, for the product's temperature
    local_sets: int  # posterior draws, each with a trajectory simulated there, for the guard's local coverage
    mismatch_alpha: float  # significance of the model-mismatch tests
    extrapolation_alpha: float  # significance of the real data's distance from the training simulations (0: off)
    mismatch_distance_ratio: float  # replay distance, posterior over prior, above which a trajectory is unexplained
    sensitivity_sims: int  # trajectories of the local sensitivity view at the nominal parameters, round 1 (0: off)


@dataclasses.dataclass
class LoggingConfig:
    plot_params: Any  # list of names, or None for the first max_plot_params
    max_plot_params: int
    plot_samples: int
    progress: bool
    figures: bool = True  # a default: run dirs written before the key load as they ran


@dataclasses.dataclass
class RunConfig:
    seed: int
    rounds: int
    device: str
    plugins: list[str]
    run_name: str
    collect: CollectConfig
    diagnostics: DiagnosticsConfig
    logging: LoggingConfig


# keys renamed in 0.2, with the new name to suggest
RENAMED = {"iterations": "rounds", "ftune": "method.finetune", "proposal": "method.proposal",
           "condition": "method.max_components and method.combination"}


def check_run_config(cfg: DictConfig) -> RunConfig:
    top = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k not in registry.GROUPS}
    old = [k for k in top if k in RENAMED]
    if old:
        raise ConfigError(f"{old[0]} was renamed to {RENAMED[old[0]]} (README: 'Renamed keys')")
    try:
        rc = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(RunConfig), top))
    except OmegaConfBaseException as exc:
        raise ConfigError(f"{exc.full_key}={exc.value!r}: {str(exc).splitlines()[0]}") from None
    c, d, lg = rc.collect, rc.diagnostics, rc.logging
    try:
        torch.device(rc.device)
    except RuntimeError as exc:
        raise ConfigError(f"device={rc.device!r} is not a torch device: {exc}") from None
    # (key, value, acceptable, what is needed): the first unacceptable one is the error, named with its value
    checks = [
        ("rounds", rc.rounds, rc.rounds >= 1, ">= 1"),
        ("collect.trajectories", c.trajectories, c.trajectories >= 20, ">= 20"),
        ("collect.horizon", c.horizon, c.horizon >= 1, ">= 1"),
        ("collect.chunk", c.chunk, c.chunk >= 1, ">= 1"),
        ("logging.max_plot_params", lg.max_plot_params, lg.max_plot_params >= 1, ">= 1"),
        ("logging.plot_samples", lg.plot_samples, lg.plot_samples >= 10, ">= 10"),
        ("diagnostics.held_out_fraction", d.held_out_fraction, 0.0 <= d.held_out_fraction < 0.5, "in [0, 0.5)"),
        ("diagnostics.coverage_samples", d.coverage_samples, d.coverage_samples >= 10, ">= 10"),
        ("diagnostics.levels", d.levels, all(0 < lv < 1 for lv in d.levels), "each in (0, 1)"),
        ("diagnostics.predictive_sims", d.predictive_sims, d.predictive_sims >= 0, ">= 0"),
        ("diagnostics.replay_sims", d.replay_sims, d.replay_sims == 0 or d.replay_sims >= 2, "0 (off) or >= 2"),
        ("diagnostics.combination_sets", d.combination_sets, d.combination_sets >= 0, ">= 0"),
        ("diagnostics.local_sets", d.local_sets, d.local_sets >= 0, ">= 0"),
        ("diagnostics.sensitivity_sims", d.sensitivity_sims, d.sensitivity_sims >= 0, ">= 0"),
        ("diagnostics.mismatch_alpha", d.mismatch_alpha, 0 < d.mismatch_alpha < 1, "in (0, 1)"),
        ("diagnostics.extrapolation_alpha", d.extrapolation_alpha, 0 <= d.extrapolation_alpha < 1, "in [0, 1)"),
        ("diagnostics.mismatch_distance_ratio", d.mismatch_distance_ratio, 0 < d.mismatch_distance_ratio < 1,
         "in (0, 1)"),
    ]
    for key, value, ok, needed in checks:
        if not ok:
            raise ConfigError(f"{key}={value}: need {key} {needed}")
    return rc

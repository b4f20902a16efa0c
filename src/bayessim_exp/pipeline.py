"""The BayesSim round loop, stage by stage, resumable from the last finished stage.

Each round: collect (simulate trajectories with parameters from the round's proposal: the
prior, or one built from the previous round's posterior, see `proposal`) -> summarize -> fit
(the posterior model; held-out simulations give its expected coverage) -> real (new real
trajectories) -> condition (the posterior given all real trajectories, with the SNPE-A
correction for the proposal). Each stage's result is written
atomically to the run dir before the next starts; a rerun in the same dir skips what is there.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from . import registry
from .artifacts import RunDir
from .errors import ConfigError, PosteriorError
from .diagnostics.coverage import expected_coverage
from .diagnostics.predictive import predictive_distances
from .inference.bayessim import condition
from .models.mixture import TruncatedMixture
from .models.proposals import TruncatedPrior, moment_matched
from .sim.pool import SimulatorPool
from .sim.trajectories import Trajectories

log = logging.getLogger(__name__)

STAGES = ("collect", "summarize", "fit", "real", "condition")

# proposal -> how rounds after the first draw their parameters (docs/statistics.md):
#   prior      always the prior; every round's simulations train the model
#   posterior  the previous posterior itself (SNPE-A; closed form only for one-component mixtures)
#   gaussian   the previous posterior moment-matched to one Gaussian (SNPE-A in closed form for mixtures)
#   truncated  the prior restricted to the previous posterior's 99.9 % HPD region (TSNPE, no correction)
PROPOSALS = ("prior", "posterior", "gaussian", "truncated")
# SNPE-A needs the model trained on draws from a single proposal: the current round's simulations only
_SINGLE_ROUND_PROPOSALS = ("posterior", "gaussian")


@dataclasses.dataclass
class CollectConfig:
    trajectories: int = 10000
    horizon: int = 50
    chunk: int = 4096
    keep_trajectories: bool = False  # keep raw simulated trajectories after summarizing


@dataclasses.dataclass
class ConditionConfig:
    max_components: int = 50


@dataclasses.dataclass
class DiagnosticsConfig:
    held_out_fraction: float = 0.1  # of each round's simulations, kept out of training for the coverage check
    coverage_samples: int = 500  # posterior draws per held-out simulation
    levels: list[float] = dataclasses.field(default_factory=lambda: [0.5, 0.9])
    predictive_sims: int = 200  # simulations at posterior and at prior draws for the predictive check (0: off)


@dataclasses.dataclass
class LoggingConfig:
    plot_params: Any = None  # list of names, or None for the first max_plot_params
    max_plot_params: int = 6
    plot_samples: int = 5000
    progress: bool = True


@dataclasses.dataclass
class RunConfig:
    """The top-level keys that are not component groups, type-checked before anything runs."""

    seed: int = 0
    iterations: int = 3
    ftune: bool = True
    device: str = "cpu"
    plugins: list[str] = dataclasses.field(default_factory=list)
    run_name: str = ""
    proposal: str = "truncated"
    collect: CollectConfig = dataclasses.field(default_factory=CollectConfig)
    condition: ConditionConfig = dataclasses.field(default_factory=ConditionConfig)
    diagnostics: DiagnosticsConfig = dataclasses.field(default_factory=DiagnosticsConfig)
    logging: LoggingConfig = dataclasses.field(default_factory=LoggingConfig)


def check_run_config(cfg: DictConfig) -> RunConfig:
    top = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k not in registry.GROUPS}
    try:
        rc = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(RunConfig), top))
    except OmegaConfBaseException as exc:
        raise ConfigError(f"{exc.full_key}={exc.value!r}: {str(exc).splitlines()[0]}") from None
    c = rc.collect
    if rc.iterations < 1 or c.trajectories < 20 or c.horizon < 1 or c.chunk < 1:
        raise ConfigError("need iterations >= 1, collect.trajectories >= 20, collect.horizon >= 1, collect.chunk >= 1")
    if rc.condition.max_components < 1 or rc.logging.max_plot_params < 1 or rc.logging.plot_samples < 10:
        raise ConfigError("need condition.max_components >= 1, logging.max_plot_params >= 1, logging.plot_samples >= 10")
    try:
        torch.device(rc.device)
    except RuntimeError as exc:
        raise ConfigError(f"device={rc.device!r} is not a torch device: {exc}") from None
    if rc.proposal not in PROPOSALS:
        raise ConfigError(f"proposal={rc.proposal!r} not allowed; allowed: {', '.join(PROPOSALS)}")
    d = rc.diagnostics
    if (not 0.0 <= d.held_out_fraction < 0.5 or d.coverage_samples < 10 or not all(0 < lv < 1 for lv in d.levels)
            or d.predictive_sims < 0):
        raise ConfigError("need 0 <= diagnostics.held_out_fraction < 0.5, diagnostics.coverage_samples >= 10, "
                          "diagnostics.levels in (0, 1), diagnostics.predictive_sims >= 0")
    return rc


def stage_seed(seed: int, round_index: int, stage: str) -> int:
    """Independent, reproducible sub-seed per (seed, round, stage)."""
    return int(np.random.SeedSequence([seed, round_index, STAGES.index(stage)]).generate_state(1)[0])


@dataclasses.dataclass
class Components:
    task: Any
    prior: Any
    sims: SimulatorPool
    summarizer: Any
    real: Any
    x_dim: int

    def policy(self, cfg: DictConfig, seed: int):
        return registry.build("policy", cfg.policy, action_dim=self.task.action_dim, seed=seed,
                              control_dt=self.task.cfg.control_dt, actor=None)

    def model(self, cfg: DictConfig):
        deps: dict[str, Any] = {"theta_dim": self.task.spec.dim, "x_dim": self.x_dim}
        if getattr(self.summarizer, "embedding", None) is not None:
            deps["embedding"] = self.summarizer.embedding
        return registry.build("model", cfg.model, **deps)


def build_components(cfg: DictConfig, rc: RunConfig) -> Components:
    """Build and check every component; all config errors surface here, before any simulation."""
    for group in registry.GROUPS:
        if group not in cfg:
            raise ConfigError(f"config has no {group!r} group; allowed: {', '.join(registry.names(group))}")
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, rc.collect.chunk)
    summarizer = registry.build("summarizer", cfg.summarizer)
    summarizer.check(rc.collect.horizon)
    x_dim = summarizer.output_dim(task.obs_dim, task.action_dim, rc.collect.horizon)
    registry.parse_params("policy", cfg.policy)
    registry.parse_params("model", cfg.model)
    registry.build("rl", cfg.rl, task=task, device=rc.device)
    real = registry.build("real", cfg.real, task=task, sims=sims)
    if rc.logging.plot_params is not None:
        task.spec.subset(rc.logging.plot_params)
    return Components(task, prior, sims, summarizer, real, x_dim)




class Pipeline:
    def __init__(self, cfg: DictConfig, out_dir: str | Path):
        self.cfg = cfg
        self.rc = check_run_config(cfg)
        registry.load_plugins(self.rc.plugins)
        self.comp = build_components(cfg, self.rc)
        self.run_dir = RunDir(out_dir)
        self.run_dir.bind_config(cfg)
        self.device = torch.device(self.rc.device)
        self._tb = None
        self._posteriors: dict[int, Any] = {}
        self._proposals: dict[int, Any] = {}

    @property
    def tb(self):
        if self._tb is None:
            from .logging.tensorboard import TensorBoardLogger

            self._tb = TensorBoardLogger(self.run_dir.path)
            self._tb.config(OmegaConf.to_yaml(self.cfg, resolve=True))
        return self._tb

    # stages --------------------------------------------------------------------------
    def collect(self, r: int) -> dict:
        seed = stage_seed(self.rc.seed, r, "collect")
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            theta = self.proposal(r).sample((self.rc.collect.trajectories,)).double()
        policy = self.comp.policy(self.cfg, seed)
        traj = self.comp.sims.rollout(theta, policy, self.rc.collect.horizon, seed, self.rc.logging.progress)
        return {"theta": theta.float(), "traj": traj.state_dict()}

    def summarize(self, r: int, collected: dict) -> dict:
        traj = Trajectories(**collected["traj"]).to(self.device)
        keep = ~traj.diverged
        x = self.comp.summarizer(traj.select(keep)).cpu()
        finite = torch.isfinite(x).all(1)
        theta = collected["theta"][keep.cpu()][finite]
        # the collect artifact may be deleted after this stage: carry its timing along
        return {"theta": theta, "x": x[finite], "diverged": int((~keep).sum()) + int((~finite).sum()),
                "collect_seconds": collected["seconds"]}

    def fit(self, r: int, model) -> dict:
        first = r if self.rc.proposal in _SINGLE_ROUND_PROPOSALS else 1
        data = [self._split(self.run_dir.load(k, "summarize")) for k in range(first, r + 1)]
        theta = torch.cat([d[0] for d in data])
        x = torch.cat([d[1] for d in data])
        if r > 1 and self.rc.ftune:
            model.load_state_dict(self.run_dir.load(r - 1, "fit")["model"])
        history = model.fit(theta, x, seed=stage_seed(self.rc.seed, r, "fit"), label=f"round {r}")
        theta_val, x_val = data[-1][2], data[-1][3]
        d = self.rc.diagnostics
        coverage = None if len(theta_val) == 0 else expected_coverage(
            model, theta_val, x_val, d.levels, d.coverage_samples, seed=stage_seed(self.rc.seed, r, "fit"))
        return {"model": model.state_dict(), "history": history, "num_train": len(theta), "coverage": coverage}

    def _split(self, summary: dict) -> tuple[torch.Tensor, ...]:
        """(theta, x) for training and (theta, x) held out for the coverage check (the last rows)."""
        n_val = int(self.rc.diagnostics.held_out_fraction * len(summary["theta"]))
        cut = len(summary["theta"]) - n_val
        return summary["theta"][:cut], summary["x"][:cut], summary["theta"][cut:], summary["x"][cut:]

    def proposal(self, r: int):
        """The distribution round r draws its parameters from (see PROPOSALS)."""
        if self.proposal_name(r) == "prior":
            return self.comp.prior
        return self._proposals[r]

    def proposal_name(self, r: int) -> str:
        """The proposal round r really uses: `truncated` falls back to the prior when the previous
        posterior's region is too small a share of the prior to sample (many parameters)."""
        if r == 1 or self.rc.proposal == "prior":
            return "prior"
        if r not in self._proposals:
            previous, seed = self.posterior(r - 1), stage_seed(self.rc.seed, r, "collect")
            if self.rc.proposal == "truncated":
                try:
                    self._proposals[r] = TruncatedPrior(self.comp.prior, previous, seed=seed)
                except ValueError as exc:
                    log.warning("round %d: %s; simulating from the prior instead", r, exc)
                    self._proposals[r] = None
            elif self.rc.proposal == "gaussian":
                self._proposals[r] = moment_matched(previous, *self._box(), seed=seed)
            else:
                self._proposals[r] = previous
        return "prior" if self._proposals[r] is None else self.rc.proposal

    def _box(self) -> tuple[torch.Tensor, torch.Tensor]:
        spec = self.comp.task.spec
        return torch.as_tensor(spec.low, dtype=torch.float64), torch.as_tensor(spec.high, dtype=torch.float64)

    def posterior(self, r: int):
        """Round r's posterior, rebuilt from its fit and real artifacts when resuming."""
        if r not in self._posteriors:
            model = self.comp.model(self.cfg)
            model.load_state_dict(self.run_dir.load(r, "fit")["model"])
            self._posteriors[r] = self.condition(r, model, self.run_dir.load(r, "real")["x"])
        return self._posteriors[r]

    def real(self, r: int) -> dict:
        seed = stage_seed(self.rc.seed, r, "real")
        policy = self.comp.policy(self.cfg, seed)
        traj = self.comp.real.collect(r, policy, self.rc.collect.horizon, seed)
        previous = self.run_dir.load(r - 1, "real")["x"] if r > 1 else None
        if traj is None:
            if previous is None:
                raise ConfigError("the real data source gave no trajectories")
            return {"x": previous, "new": 0}
        x_new = self.comp.summarizer(traj.to(self.device)).cpu()
        x = x_new if previous is None else torch.cat([previous, x_new])
        return {"x": x, "new": len(x_new), "traj": traj.state_dict()}

    def condition(self, r: int, model, x_real: torch.Tensor):
        try:
            post = condition(model, x_real, self.comp.prior, self.rc.condition.max_components,
                             proposal=self.proposal(r), seed=stage_seed(self.rc.seed, r, "condition"))
        except ValueError as exc:
            raise PosteriorError(f"round {r}: {exc}") from exc
        self._posteriors[r] = post
        return post

    # the loop ------------------------------------------------------------------------
    def run(self, stop_after: tuple[int, str] | None = None) -> dict:
        """Run every round; `stop_after=(round, stage)` returns early there (tests of resuming)."""
        names = self.comp.task.spec.names
        true = self.comp.real.true_params
        results = {
            "task": self.cfg.task.name, "model": self.cfg.model.name, "summarizer": self.cfg.summarizer.name,
            "policy": self.cfg.policy.name, "seed": self.rc.seed, "run_name": self.rc.run_name,
            "param_names": names, "true_params": None if true is None else dict(zip(names, map(float, true))),
            "prior": {"low": dict(zip(names, map(float, self.comp.task.spec.low))),
                      "high": dict(zip(names, map(float, self.comp.task.spec.high)))},
            "rounds": [],
        }
        epochs_logged = 0
        for r in range(1, self.rc.iterations + 1):
            model = self.comp.model(self.cfg)

            def stage(name: str, fn: Callable[[], Any]) -> Any:
                if self.run_dir.has(r, name):
                    return self.run_dir.load(r, name)
                t0 = time.perf_counter()
                out = fn()
                out["seconds"] = time.perf_counter() - t0
                self.run_dir.save(r, name, out)
                log.info("round %d: %s done in %.1f s", r, name, out["seconds"])
                if stop_after == (r, name):
                    raise _Stop
                return out

            try:
                if not self.run_dir.has(r, "summarize"):
                    collected = stage("collect", lambda: self.collect(r))
                    stage("summarize", lambda: self.summarize(r, collected))
                    if not self.rc.collect.keep_trajectories:
                        self.run_dir.stage_file(r, "collect").unlink(missing_ok=True)
                summary = self.run_dir.load(r, "summarize")
                fitted = stage("fit", lambda: self.fit(r, model))
                model.load_state_dict(fitted["model"])
                real = stage("real", lambda: self.real(r))
                cond = stage("condition", lambda: self._condition_record(r, model, real["x"], true))
            except _Stop:
                return results
            seconds = {"collect": summary["collect_seconds"], "summarize": summary["seconds"], "fit": fitted["seconds"],
                       "real": real["seconds"], "condition": cond["seconds"]}
            seconds = {k: round(float(v), 3) for k, v in seconds.items()}
            hist = fitted["history"]
            self.tb.losses(r, hist, epochs_logged)
            epochs_logged += hist["epochs"]
            record = {
                "round": r,
                "sim_trajectories": self.rc.collect.trajectories,
                "train_set_size": fitted["num_train"],
                "diverged": summary["diverged"],
                "real_trajectories": int(real["x"].shape[0]),
                "epochs": hist["epochs"],
                "train_loss": hist["train"][-1],
                "val_loss": hist["best_val"],
                "proposal": self.proposal_name(r),
                "coverage": fitted.get("coverage"),
                **cond["metrics"],
                "surrogate_real_return": None,
                "seconds": seconds,
            }
            results["rounds"].append(record)
            self.run_dir.write_json("results.json", results)
            self.tb.scalars(r, {"posterior/log_prob_true": record["log_prob_true_posterior"],
                                "posterior/log_prob_gain_over_prior": record["log_prob_gain"],
                                "sim/diverged": record["diverged"],
                                **{f"predictive_distance/{k}": v for k, v in (record["predictive_distance"] or {}).items()},
                                **{f"coverage/{kind}_{level}": value
                                   for kind, levels in (record["coverage"] or {}).items() for level, value in levels.items()}})
        if self._tb is not None:
            self._tb.close()
        return results

    def _condition_record(self, r: int, model, x_real: torch.Tensor, true: np.ndarray | None) -> dict:
        posterior = self.condition(r, model, x_real)
        names = self.comp.task.spec.names
        mean, std = posterior.moments()
        prior = self.comp.prior
        metrics = {
            "posterior_mean": dict(zip(names, mean.tolist())),
            "posterior_std": dict(zip(names, std.tolist())),
            "prior_std": dict(zip(names, prior.stddev.double().tolist())),
            "log_prob_true_posterior": None, "log_prob_true_prior": None, "log_prob_gain": None,
            "predictive_distance": self._predictive(r, posterior, x_real),
        }
        if true is not None:
            t = torch.as_tensor(true, dtype=torch.float64)[None]
            lp_post, lp_prior = float(posterior.log_prob(t)), float(prior.log_prob(t))
            metrics.update(log_prob_true_posterior=lp_post, log_prob_true_prior=lp_prior,
                           log_prob_gain=lp_post - lp_prior)
        lc = self.rc.logging
        plot_names = list(lc.plot_params) if lc.plot_params is not None else names[: lc.max_plot_params]
        self.tb.posterior(r, posterior, prior, names, plot_names, true, lc.plot_samples)
        # mixtures are stored; other posteriors (flows, importance-weighted) are rebuilt from the fit and real artifacts
        state = posterior.state_dict() if isinstance(posterior, TruncatedMixture) else None
        return {"posterior": state, "metrics": metrics}


    def _predictive(self, r: int, posterior, x_real: torch.Tensor) -> dict | None:
        num = self.rc.diagnostics.predictive_sims
        if num == 0:
            return None
        seed = stage_seed(self.rc.seed, r, "condition")

        def simulate_summaries(theta: torch.Tensor) -> torch.Tensor:
            traj = self.comp.sims.rollout(theta, self.comp.policy(self.cfg, seed), self.rc.collect.horizon,
                                          seed).to(self.device)
            x = self.comp.summarizer(traj.select(~traj.diverged)).cpu()
            return x[torch.isfinite(x).all(1)]

        return predictive_distances(simulate_summaries, x_real, posterior, self.comp.prior, num, seed)


class _Stop(Exception):
    """Raised after the requested stage to imitate a killed run."""


def run(cfg: DictConfig, out_dir: str | Path, stop_after: tuple[int, str] | None = None) -> dict:
    return Pipeline(cfg, out_dir).run(stop_after)

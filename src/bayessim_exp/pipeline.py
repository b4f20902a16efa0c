"""The round loop (the paper's Figure 1), stage by stage, resumable from the last finished stage.

Each round: `real` records new real trajectories (kept raw across rounds), the inference method's
stages turn simulations and real data into a new distribution over the parameters (BayesSim:
collect -> summarize -> fit -> condition), `score` measures it against the prior and the true
parameters when known, then the RL component's stages (none with rl=none) train and evaluate a policy on it.
Every stage writes its artifact atomically before the next starts; a rerun in the same dir skips
what is there. results.json is rewritten after every round. The method may add rounds past `rounds` after
the last planned one (BayesSim: an escape under way); results.json's rounds_planned says how many the run
goes to, so a run killed inside an added round reads as unfinished.

The pipeline builds each object and hands it to those that use it: the components (components.py), then the
RL component with the round's distribution as a callable (the method's posterior, bound late), then the
method with a MethodInputs whose collect policy acts with the RL component's actor. A stage reaches its
dependencies through the object it belongs to; its context (stages.RoundContext) holds only the round.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from . import registry
from .artifacts import RunDir
from .components import CollectPolicies, build_components, build_method, build_rl
from .diagnostics.scoring import score
from .distributions.base import ParameterDistribution
from .distributions.independent import BoxUniform
from .errors import ConfigError, PosteriorError
from .inference.base import InferenceMethod, handed_on_name
from .run_config import check_run_config
from .sim.trajectories import Trajectories
from .stages import RoundContext, Stage, check_stages, run_stage

log = logging.getLogger(__name__)


class Pipeline:
    def __init__(self, cfg: DictConfig, out_dir: str | Path, drawing_process: bool = True):
        """drawing_process=False: TensorBoard's figures drawn in this process (logging/tensorboard.py)."""
        self.rc = check_run_config(cfg)
        registry.load_plugins(self.rc.plugins)
        comp = build_components(cfg, self.rc)  # every config error surfaces here or below, before any simulation
        self.cfg = cfg = comp.cfg  # with this machine's choices: what config.yaml records
        self.task, self.prior, self.real_source = comp.task, comp.prior, comp.real
        self.integrators = comp.integrators  # what the method's simulations alternated between (sim/integrators.py)
        self.rl = build_rl(cfg, comp, self._posterior)
        self.policy: CollectPolicies = dataclasses.replace(comp.policy, actor=self.rl.actor)
        self.method: InferenceMethod = build_method(cfg, comp, self.policy)
        self.run_dir = RunDir(out_dir)
        self.run_dir.bind_config(cfg)
        self.run_dir.bind_fingerprint("real data", self.real_source.fingerprint)
        self.stages = [Stage("real", self.real), *self.method.stages(), Stage("score", self.score),
                       *self.rl.stages()]
        check_stages(self.stages)
        self._tb, self._drawing_process = None, drawing_process

    @property
    def tb(self):
        if self._tb is None:
            from .logging.tensorboard import TensorBoardLogger

            self._tb = TensorBoardLogger(self.run_dir.path, self._drawing_process, self.rc.logging.figures)
            self._tb.config(OmegaConf.to_yaml(self.cfg, resolve=True))
        return self._tb

    def _posterior(self, ctx: RoundContext) -> ParameterDistribution:
        """The round's distribution, for the RL component (built before the method it asks)."""
        return self.method.posterior(ctx)

    # the stages the pipeline owns ------------------------------------------------------
    def real(self, ctx: RoundContext) -> dict:
        """New real trajectories under the collect policy, appended to the earlier rounds' (kept raw)."""
        traj = self.real_source.collect(ctx.round, self.policy(ctx.seed, ctx), self.rc.collect.horizon, ctx.seed)
        previous = Trajectories(**ctx.output("real", ctx.round - 1)["traj"]) if ctx.round > 1 else None
        if traj is None:
            if previous is None:
                raise ConfigError("the real data source gave no trajectories")
            return {"traj": previous.state_dict(), "new": 0}
        merged = traj if previous is None else Trajectories.cat([previous, traj])
        return {"traj": merged.state_dict(), "new": traj.num}

    def score(self, ctx: RoundContext) -> dict:
        """The round's distribution against the prior (and the true parameters when known), plotted, with whose
        distribution it is: the round's own posterior, or what the round handed on instead."""
        posterior = self.method.posterior(ctx)
        source = self.method.handed_on_round(ctx)
        names = self.task.spec.names
        true = self.real_source.true_params
        lc = self.rc.logging
        plot_names = list(lc.plot_params) if lc.plot_params is not None else names[: lc.max_plot_params]
        spec = self.task.spec
        title = (f"posterior, round {ctx.round}" if source == ctx.round
                 else f"{handed_on_name(source)}, handed on in round {ctx.round}")
        ctx.tb.posterior(ctx.round, posterior, self.prior, names, plot_names, true, lc.plot_samples,
                         spec.low, spec.high, title, flat=source == 0 and isinstance(self.prior, BoxUniform))
        return {**score(posterior, self.prior, names, true, ctx.seed),
                "handed_on": {"round": source, "name": handed_on_name(source)}}

    # the loop ------------------------------------------------------------------------
    def run(self, stop_after: tuple[int, str] | None = None) -> dict:
        """Run every round; `stop_after=(round, stage)` returns early there (tests of resuming)."""
        names = self.task.spec.names
        true = self.real_source.true_params
        results: dict[str, Any] = {
            "task": self.cfg.task.name, "method": self.cfg.method.name, "model": self.cfg.model.name,
            "summarizer": self.cfg.summarizer.name, "policy": self.cfg.policy.name, "seed": self.rc.seed,
            "run_name": self.rc.run_name, "param_names": names,
            "true_params": None if true is None else dict(zip(names, map(float, true))),
            # where the truth comes from (real.truth: task, prior, nominal); None for recorded data
            "truth_source": self.cfg.real.get("truth"),
            # the integrators the method's slots alternated between ([] for a method without them)
            "integrators": list(self.integrators),
            "prior": {"low": dict(zip(names, map(float, self.task.spec.low))),
                      "high": dict(zip(names, map(float, self.task.spec.high)))},
            "rounds": [],
            # the rounds this run goes to: `rounds`, plus those the method added after the last planned one
            # (BayesSim: an escape under way, method.escape_rounds), each with why
            "rounds_planned": self.rc.rounds,
            "rounds_added": [],
        }
        try:
            r = 0
            while r < results["rounds_planned"]:
                r += 1
                ctx = RoundContext(self.run_dir, r, self.rc.seed, self.tb)
                seconds = {}
                for stage in self.stages:
                    if run_stage(ctx, stage):
                        self._shrink_transients(ctx)
                        if stop_after == (r, stage.name):
                            return results
                self._shrink_transients(ctx)  # also what a run killed before its shrink left in a resumed round
                for stage in self.stages:
                    if self.run_dir.has(r, stage.name):
                        seconds[stage.name] = round(float(ctx.output(stage.name)["seconds"]), 3)
                recording = ctx.at("record")
                record = self._record(recording, seconds)
                results["rounds"].append(record)
                if "handed_on" in record:  # absent from rounds scored before it was recorded (a resumed run)
                    results["handed_on"] = record["handed_on"]  # what domain randomization gets after the last round
                if r == results["rounds_planned"] and (why := self.method.added_round(recording)) is not None:
                    log.warning("%s", why)
                    results["rounds_planned"] += 1
                    results["rounds_added"].append({"round": r + 1, "why": why})
                self.run_dir.write_json("results.json", results)
                self.tb.scalars(r, _numbers(record))
                reason = self.method.stop_reason(recording)
                if reason is not None:
                    raise PosteriorError(reason)
        finally:  # also after a failing stage: the figures drawn so far reach TensorBoard
            if self._tb is not None:
                self._tb.close()
                self._tb = None
        return results

    def _shrink_transients(self, ctx: RoundContext) -> None:
        """A transient artifact shrinks to its timing once every stage that reads it has finished."""
        for stage in self.stages:
            readers = [s.name for s in self.stages if stage.name in s.inputs]
            if (stage.transient and all(self.run_dir.has(ctx.round, n) for n in [stage.name, *readers])
                    and set(ctx.output(stage.name)) != {"seconds"}):
                shrunk = {"seconds": ctx.output(stage.name)["seconds"]}
                self.run_dir.save(ctx.round, stage.name, shrunk)
                ctx.remember(stage.name, shrunk)

    def _record(self, ctx: RoundContext, seconds: dict) -> dict:
        record = {"round": ctx.round, "real_trajectories": int(ctx.output("real")["traj"]["states"].shape[0])}
        record.update(self.method.record(ctx))
        record.update({k: v for k, v in ctx.output("score").items() if k != "seconds"})
        record.update(self.rl.record(ctx))
        record["seconds"] = seconds
        return record


def _numbers(record: dict, prefix: str = "") -> dict[str, float]:
    """A round's record as TensorBoard tags (nested keys joined by '/'): numbers as they are, verdicts
    (booleans) as 0/1 and lists of findings (warnings, reasons) by their count."""
    out: dict[str, float] = {}
    for key, value in record.items():
        tag = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_numbers(value, tag + "/"))
        elif isinstance(value, (bool, int, float, np.floating)) and key != "round":
            out[tag] = float(value)
        elif key in ("warnings", "reasons"):
            out[tag] = float(len(value))
    return out


def run(cfg: DictConfig, out_dir: str | Path, stop_after: tuple[int, str] | None = None,
        drawing_process: bool = True) -> dict:
    return Pipeline(cfg, out_dir, drawing_process).run(stop_after)


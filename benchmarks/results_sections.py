"""The sections of docs/results.md (benchmarks/results.py assembles them): each declares the jobs (commands) its
experiment runs and renders its markdown from their outputs. Prose that quotes no number lives in
benchmarks/results_templates/<name>.md; every sentence with a number is written here from the measured values.

A section has `name`, `jobs(ctx) -> [Job]` and `render(ctx, stamp) -> markdown`. Besides the built-in ones,
ScriptSection(name, script, args, quick_args) is a script that prints its section (heading first) to stdout.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import itertools
import json
import math
import statistics
import sys
from pathlib import Path
from string import Template
from types import ModuleType

import numpy as np
from omegaconf import OmegaConf

import methods  # benchmarks/methods.py, beside this module
from bayessim_exp.report.calibration import LEVELS, Calibration, calibration, clopper_pearson, share_text
from bayessim_exp.report.jobs import read_jobs

ROOT = Path(__file__).resolve().parents[1]
TEMPLATES = ROOT / "benchmarks" / "results_templates"

# every job runs on the CPU on one thread, so that 14 jobs share 16 cores without a GPU in the way
CPU_JOB = ["sim=native", "sim.nthread=1", "device=cpu", "logging.progress=false"]
# PPO on the GPU with MuJoCo Warp, the batch of docs/benchmarks.md's "RL at GPU speed" (8,192 x 16, 5 x 32,768)
GPU_PPO = ["sim=mjx", "sim.impl=warp", "device=cuda", "rl.train.num_envs=8192", "rl.train.rollout_steps=16",
           "rl.train.minibatch_size=32768", "rl.train.epochs=5"]


class SectionError(RuntimeError):
    """A section's jobs did not leave what its text needs."""


@dataclasses.dataclass
class Job:
    name: str               # unique, also its log's name
    argv: list[str]
    cost: float             # estimated seconds on one core at the full budget: the longest start first
    stdout: Path | None = None  # where stdout goes (stderr to the log); None: both to the log
    gpu: bool = False       # runs on one GPU of those results.py shares out (CUDA_VISIBLE_DEVICES)


@dataclasses.dataclass
class Context:
    work: Path              # this section's runs and outputs (emptied before its jobs start)
    figures: Path           # where figures go (docs/figures in the full mode)
    quick: bool
    jobs: int               # processes at a time, quoted in the text


def template(name: str) -> Template:
    return Template((TEMPLATES / f"{name}.md").read_text())


@functools.cache
def script(name: str) -> ModuleType:
    """scripts/<name>.py, whose constants and plots the RL sections share with the script their jobs run. Loaded
    from its file, as scripts/ is no package, and only where a section needs it: the scripts import torch."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def python_command(argv: list[str]) -> str:
    """A job's command as the text quotes it: `python ...`, without the work directories it was given."""
    shown, skip = ["python"], False
    for arg in argv[1:]:
        if not skip and not arg.startswith("hydra.run.dir=") and arg not in ("--out", "--run-dir"):
            shown.append(arg)
        skip = arg in ("--out", "--run-dir")
    return " ".join(shown)


def spread(values: list[float], fmt: str) -> str:
    lo, hi = min(values), max(values)
    return format(lo, fmt) if format(lo, fmt) == format(hi, fmt) else f"{lo:{fmt}}–{hi:{fmt}}"


class MethodsSection:
    """BayesSim, SimOpt and MuJoCo's sysid: the jobs of sweeps/methods.yaml at each task's own truth, one process
    each, SimOpt in closed loop, and a known-truth study (sweeps/calibration.yaml) of every method on every task."""

    name = "methods"
    sweep = ROOT / "sweeps" / "methods.yaml"
    truths = 20  # known truths per task and method (2 when quick): the same truths for every method (seeds 0..)
    costs = {("Cartpole", "bayessim"): 240, ("Cartpole", "simopt"): 150, ("Cartpole", "sysid"): 60,
             ("Pendulum", "bayessim"): 120, ("Pendulum", "simopt"): 60, ("Pendulum", "sysid"): 30}

    def grid(self, quick: bool) -> list[dict]:
        params = OmegaConf.to_container(OmegaConf.load(self.sweep).hydra.sweeper.params)
        values = {k: _sweep_values(str(v)) for k, v in params.items()}
        if quick:
            values = {"task": ["Pendulum"], "method": values["method"], "seed": [0]}
        return [dict(zip(values, combo)) for combo in itertools.product(*values.values())]

    def pairs(self, quick: bool) -> list[tuple[str, str]]:
        return sorted({(p["task"], p["method"]) for p in self.grid(quick)})

    def jobs(self, ctx: Context) -> list[Job]:
        out = []
        for point in self.grid(ctx.quick):
            label = f"{point['task']}_{point['method']}_seed{point['seed']}"
            argv = [sys.executable, "-m", "bayessim_exp", *[f"{k}={v}" for k, v in point.items()], *CPU_JOB,
                    *self._budget(ctx), f"hydra.run.dir={ctx.work / 'sweep' / label}"]
            out.append(Job(f"methods/{label}", argv, self.costs.get((point["task"], point["method"]), 120)))
        for task, method in self.pairs(ctx.quick):
            for seed in range(2 if ctx.quick else self.truths):
                argv = [sys.executable, "-m", "bayessim_exp", "--config-dir", "sweeps", "--config-name", "calibration",
                        f"task={task}", f"method={method}", f"seed={seed}", *CPU_JOB, *self._budget(ctx),
                        f"hydra.run.dir={ctx.work / 'calibration' / f'{task}_{method}' / f'seed{seed}'}"]
                out.append(Job(f"methods/calibration_{task}_{method}_seed{seed}", argv, self.costs.get((task, method), 120)))
        return out + [self._closed_loop_job(ctx)]

    @staticmethod
    def _budget(ctx: Context) -> list[str]:
        # one round when quick: the section reads each run's last round only, and a round is a third of a job
        return ["debug=smoke", "rounds=1"] if ctx.quick else []

    def _closed_loop_job(self, ctx: Context) -> Job:
        argv = [sys.executable, "-m", "bayessim_exp", "task=Pendulum", "method=simopt", "method.rollout=closed_loop",
                "seed=0", *CPU_JOB, *self._budget(ctx), f"hydra.run.dir={ctx.work / 'closed_loop'}"]
        return Job("methods/closed_loop", argv, 60)

    def render(self, ctx: Context, stamp: str) -> str:
        runs = methods.finished_runs([ctx.work / "sweep"])
        expected = set(self.pairs(ctx.quick))
        if set(runs) != expected or len({len(v) for v in runs.values()}) != 1:
            raise SectionError(f"finished runs {sorted((k, len(v)) for k, v in runs.items())}, expected {sorted(expected)}")
        closed = methods.finished_runs([ctx.work / "closed_loop"])
        if not closed:
            raise SectionError("the closed-loop run did not finish")
        budget = " ".join(["", *self._budget(ctx)])
        commands = (f"python -m bayessim_exp task=T method=M seed=S {' '.join(CPU_JOB)}{budget}   # each (T, M, S) "
                    f"of sweeps/methods.yaml\n{python_command(self._closed_loop_job(ctx).argv)}")
        studies = self._studies(ctx)
        truths = len(next(iter(studies.values()))[1])
        study_command = (f"python -m bayessim_exp --config-dir sweeps --config-name calibration task=T method=M seed=S "
                         f"{' '.join(CPU_JOB)}{budget}   # S = 0..{truths - 1}, each (T, M) above")
        reading = [self._task_bullet(task, runs) for task in sorted({t for t, _ in runs})]
        reading.append(self._closed_loop_bullet(runs, next(iter(closed.values()))[0]))
        sweep_dir = ctx.work / "sweep"
        return template(self.name).substitute(
            stamp=stamp, settings=self._settings(runs), commands=commands, jobs=len(self.grid(ctx.quick)),
            table=methods.table(runs), sweep_dir=sweep_dir.relative_to(ROOT) if sweep_dir.is_relative_to(ROOT) else sweep_dir,
            seeds=", ".join(str(r["seed"]) for _, r in next(iter(runs.values()))), parallel=ctx.jobs,
            reading="\n".join(reading), truths=truths, study_command=study_command,
            study_table=self._study_table(studies), study_reading="\n".join(self._study_bullets(studies)))

    def _studies(self, ctx: Context) -> dict[tuple[str, str], tuple[Calibration, list[float]]]:
        """(task, method) -> the calibration of its known-truth runs and each run's mean error / range."""
        studies = {}
        for task, method in self.pairs(ctx.quick):
            jobs = read_jobs(ctx.work / "calibration" / f"{task}_{method}")
            finished = [j for j in jobs if j.status == "finished"]
            found = calibration(finished)
            if found is None or found.jobs != len(jobs) or not jobs:
                raise SectionError(f"{task} {method}: {len(finished)} of {len(jobs)} known-truth runs finished with a truth")
            studies[(task, method)] = (found, [methods.last_round(j.results, j.path)["mean error / range"]
                                               for j in finished])
        return studies

    @staticmethod
    def _study_table(studies: dict) -> str:
        lines = ["| task | method | truths | inside the 50 % region | inside the 90 % region | gain at the truth "
                 "(quartiles, nats) | gain > 0 | mean error / range (median, quartiles) | guard failed / mismatch "
                 "flagged (final round) |", "|---|---|---:|---|---|---|---:|---|---|"]
        for (task, method), (c, errors) in sorted(studies.items()):
            shares = []
            for level in LEVELS:
                k, n = c.final_inside[level]
                shares.append(f"{share_text(k, n)}{_verdict(k, n, level)}")
            gains = [g if g is not None else -math.inf for g in c.gains]
            q1, q2, q3 = (float(v) for v in np.quantile(gains, (0.25, 0.5, 0.75)))
            e1, e2, e3 = (float(v) for v in np.quantile(errors, (0.25, 0.5, 0.75)))
            lines.append(f"| {task} | {method} | {c.jobs} | {shares[0]} | {shares[1]} | {q1:+.2f} / {q2:+.2f} / "
                         f"{q3:+.2f} | {sum(g > 0 for g in gains)} | {e2:.3g} ({e1:.3g}–{e3:.3g}) | "
                         f"{c.guard_failed_final} / {c.flagged_final} |")
        return "\n".join(lines)

    @staticmethod
    def _study_bullets(studies: dict) -> list[str]:
        bullets = []
        for task in sorted({t for t, _ in studies}):
            found = {m: studies[(t, m)] for t, m in studies if t == task}
            held = ", ".join(f"{m} {c.final_inside[0.9][0]} of {c.final_inside[0.9][1]}{_verdict(*c.final_inside[0.9], 0.9)}"
                             for m, (c, _) in sorted(found.items()))
            closest = min(found, key=lambda m: statistics.median(found[m][1]))
            bullets.append(f"- **{task}**: truths inside the final 90 % region: {held}. Closest to the truths "
                           f"(median mean error / range): {closest}, {statistics.median(found[closest][1]):.3g}.")
        return bullets

    @staticmethod
    def _settings(runs: dict) -> str:
        cfgs = {key: OmegaConf.load(found[0][0] / "config.yaml") for key, found in runs.items()}
        any_cfg = next(iter(cfgs.values()))
        bayessim = {t: c for (t, m), c in sorted(cfgs.items()) if m == "bayessim"}
        simopt = next((c for (_, m), c in cfgs.items() if m == "simopt"), None)
        sysid = next((c for (_, m), c in cfgs.items() if m == "sysid"), None)
        text = (f"Default settings of every method: {any_cfg.rounds} rounds, {any_cfg.real.per_round} new surrogate-real "
                f"roll-out(s) per round ({any_cfg.collect.horizon} steps, `{any_cfg.policy.name}` collect policy), "
                f"{any_cfg.collect.trajectories:,} parameter draws per round.")
        if bayessim:
            first = next(iter(bayessim.values()))
            text += (f" BayesSim (`method.proposal={first.method.proposal} method.parameter_space="
                     f"{first.method.parameter_space}`) with each task's defaults: " + ", ".join(
                         f"{t} `model={c.model.name} summarizer={c.summarizer.name}`" for t, c in bayessim.items()) + ".")
        if simopt is not None:
            text += (f" SimOpt: {simopt.method.updates} REPS updates of "
                     f"{simopt.collect.trajectories // simopt.method.updates:,} draws per round, each draw rolled out "
                     f"from every real roll-out's start (`method.rollout={simopt.method.rollout}`).")
        if sysid is not None:
            text += (f" sysid (MuJoCo's `mujoco.sysid`): per round {sysid.method.starts} Gauss-Newton runs of up to "
                     f"{sysid.method.max_iters} iterations replaying the real actions from the real starts, the best "
                     f"kept, and a Gaussian of its confidence intervals (noise floor `method.min_noise_std` = "
                     f"{sysid.method.min_noise_std} of each observation's spread).")
        return text

    @staticmethod
    def _task_bullet(task: str, runs: dict) -> str:
        found = {m: f for (t, m), f in sorted(runs.items()) if t == task}
        error = {m: statistics.fmean(methods.last_round(r, d)["mean error / range"] for d, r in f)
                 for m, f in found.items()}
        gain = {m: statistics.fmean(r["rounds"][-1]["log_prob_gain"] for _, r in f) for m, f in found.items()}
        names = next(iter(found.values()))[0][1]["param_names"]
        closest = min(error, key=error.get)
        text = (f"- **{task}** ({len(names)} parameters, means over {len(next(iter(found.values())))} seeds): mean "
                f"error / range " + ", ".join(f"{error[m]:.2g} ({m})" for m in found) + f", {closest} closest; gain "
                f"over the prior " + ", ".join(f"{gain[m]:+.2f} ({m})" for m in found) + " nats.")
        s = found.get("simopt")
        if s:
            min_std = OmegaConf.load(s[0][0] / "config.yaml").method.min_std
            floored = sum(all(_last(r, "posterior_std")[n] <= 1.02 * min_std * _width(r, n) for n in names) for _, r in s)
            if floored:
                text += (f" SimOpt's spread sits at its floor (`method.min_std` = {min_std} of each range) in {floored} "
                         f"of {len(s)} seeds: its log density at the truth there is the floor's, not a measured "
                         f"uncertainty.")
        worst = max(names, key=lambda n: max(statistics.fmean(abs(_last(r, "posterior_mean")[n] - r["true_params"][n])
                                                               / _width(r, n) for _, r in f) for f in found.values()))
        true = next(iter(found.values()))[0][1]["true_params"][worst]
        described = []
        for method, f in found.items():
            means = [_last(r, "posterior_mean")[worst] for _, r in f]
            stds = [_last(r, "posterior_std")[worst] for _, r in f]
            sigmas = [abs(m - true) / sd for m, sd in zip(means, stds)]
            described.append(f"{method} {spread(means, '.3g')} ± {spread(stds, '.2g')}, the truth "
                             f"{spread(sigmas, '.1f')} of its standard deviations away")
        return text + f" The parameter missed most is `{worst}` (true {true:.3g}): " + "; ".join(described) + "."

    @staticmethod
    def _closed_loop_bullet(runs: dict, closed: tuple[Path, dict]) -> str:
        run_dir, r = closed
        names = r["param_names"]
        recorded_dir, recorded = next((d, res) for d, res in runs[("Pendulum", "simopt")] if res["seed"] == r["seed"])
        ended = ", ".join(f"{n} {_last(r, 'posterior_mean')[n]:.3g} ± {_last(r, 'posterior_std')[n]:.2g} "
                          f"(true {r['true_params'][n]:.3g})" for n in names)
        error = methods.last_round(r, run_dir)["mean error / range"]
        error_recorded = methods.last_round(recorded, recorded_dir)["mean error / range"]
        return (f"- **Closed loop with the random policy**: the Pendulum run with `method.rollout=closed_loop` (seed "
                f"{r['seed']}, fresh random actions in every simulation) ended at {ended}: mean error {error:.2g} of the "
                f"range against {error_recorded:.2g} with `recorded` (same seed), {_last(r, 'log_prob_true_posterior'):+.2f} "
                f"nats at the truth, {_last(r, 'log_prob_gain'):+.2f} against the prior.")


class RlSection:
    """PPO trained on the posterior, on the prior and on nominal parameters (scripts/rl_posterior_vs_prior.py), one
    process per seed; the figure and its JSON go to ctx.figures."""

    name = "rl_posterior_vs_prior"
    seeds = (0, 1, 2)

    def _argv(self, ctx: Context, seed: int) -> list[str]:
        budget = ["--rounds", "1", "--episodes", "2", "--overrides", *CPU_JOB, "debug=smoke"] if ctx.quick else [
            "--overrides", *CPU_JOB]
        return [sys.executable, "scripts/rl_posterior_vs_prior.py", "--seeds", str(seed), *budget,
                "--out", str(ctx.work / f"seed{seed}"), "--run-dir", str(ctx.work / "runs")]

    def jobs(self, ctx: Context) -> list[Job]:
        seeds = self.seeds[:1] if ctx.quick else self.seeds
        return [Job(f"{self.name}/seed{seed}", self._argv(ctx, seed), 330) for seed in seeds]

    def render(self, ctx: Context, stamp: str) -> str:
        plot = script("rl_posterior_vs_prior").plot
        parts = [json.loads((ctx.work / f"seed{s}.json").read_text()) for s in
                 (self.seeds[:1] if ctx.quick else self.seeds)]
        results = {**parts[0], "runs": [run for p in parts for run in p["runs"]]}
        ctx.figures.mkdir(parents=True, exist_ok=True)
        (ctx.figures / f"{self.name}.json").write_text(json.dumps(results, indent=1))
        plot(results, ctx.figures / f"{self.name}.png")
        return template(self.name).substitute(stamp=stamp, **self._values(ctx, results))

    def _values(self, ctx: Context, results: dict) -> dict:
        runs, cfg = results["runs"], results["settings"]
        real = dict(kv.split("=") for kv in results["real"])
        mass, length = float(real["mass"]), float(real["length"])
        low, high = cfg["prior"]["low"], cfg["prior"]["high"]
        names = ("posterior", "prior", "nominal")
        labels = (f"round-{results['rounds']} posterior", "uniform prior", "nominal (the MJCF's)")
        score = {n: [r[n]["surrogate_real_return"]["mean"] for r in runs] for n in names}
        sd = {n: f"{statistics.stdev(v):.1f}" if len(v) > 1 else "-" for n, v in score.items()}
        rows = [f"| {label} | " + " | ".join(f"{v:.1f}" for v in score[n]) + f" | **{statistics.fmean(score[n]):.1f}** | "
                f"{sd[n]} |" for n, label in zip(names, labels)]
        seeds = [r["seed"] for r in runs]
        margins = [post - max(prior, nominal) for post, prior, nominal in zip(*score.values())]
        best = [m for m in margins if m > 0]
        order = sorted(names, key=lambda n: -statistics.fmean(score[n]))
        posterior = "; ".join(f"seed {r['seed']}: " + ", ".join(
            f"{n} {m:.3g} ± {s:.2g}" for n, m, s in zip(("mass", "length"), r["posterior_mean"], r["posterior_std"]))
            for r in runs)
        ppo_seconds = [r[n]["rl_training"]["seconds"] for r in runs for n in names]
        what = [
            f"- The posterior-trained policy scored best on {len(best)} of {len(runs)} seeds"
            + (f", by {spread(best, '.0f')} over the next best there" if best else "")
            + ". Ordered by the mean over seeds: " + ", ".join(f"{n} {statistics.fmean(score[n]):.1f}" for n in order) + ".",
            f"- Best and worst of the {cfg['episodes']} episodes, per seed: " + "; ".join(
                f"{n} " + ", ".join(f"{r[n]['surrogate_real_return']['max']:.0f} / {r[n]['surrogate_real_return']['min']:.0f}"
                                    for r in runs) for n in names) + ".",
            "- PPO's mean training return in its last batch, per seed (on the distribution it trained on): " + "; ".join(
                f"{n} " + ", ".join(_number(r[n]["rl_training"]["last_episode_return"]) for r in runs) for n in names) + ".",
        ]
        return {
            "task": results["task"], "mass": f"{mass:g}", "length": f"{length:g}",
            "mass_low": f"{low['mass']:g}", "mass_high": f"{high['mass']:g}",
            "length_low": f"{low['length']:g}", "length_high": f"{high['length']:g}",
            "torque": f"{mass * 9.81 * length / 2:.1f}", "seeds": ", ".join(map(str, seeds)), "n_seeds": len(seeds),
            "rounds": results["rounds"], "trajectories": f"{cfg['trajectories']:,}", "summarizer": cfg["summarizer"],
            "model": cfg["model"], "proposal": cfg["proposal"], "ppo_steps": f"{cfg['ppo_steps']:,}",
            "ppo_envs": cfg["ppo_envs"], "episodes": cfg["episodes"], "episode_length": cfg["episode_length"],
            "command": python_command(self._argv(ctx, 0)).replace("--seeds 0", "--seeds S"),
            "header": "| trained on | " + " | ".join(f"seed {s}" for s in seeds) + " | mean over seeds | sd over seeds |",
            "rule": "|---|" + "---:|" * (len(seeds) + 2), "rows": "\n".join(rows), "posteriors": posterior,
            "bayessim_seconds": spread([r["bayessim_seconds"] for r in runs], ".0f"),
            "ppo_seconds": spread(ppo_seconds, ".0f"), "parallel": ctx.jobs, "what": "\n".join(what),
        }


class RobotsSection:
    """BayesSim's headline on robots (scripts/rl_on_robots.py): per task, PPO on the round-1 and last-round
    posteriors, on the uniform prior and on the nominal model, over surrogate real settings x seeds. Jobs: one per
    (setting, seed) for BayesSim and the posteriors' policies, one per seed for the baselines' (trained once,
    scored on every setting). The per-task JSON and the figure go to ctx.figures. A section with `needs_gpu` trains
    PPO on a GPU in the full mode; its quick mode runs the same code on the CPU at smoke budgets, each task's study
    as one job (Cartpole's quick jobs already split a study as the full mode does)."""

    # surrogate real episodes of 100 steps: scoring the policies on 1,000-step episodes (Ant, Humanoid) was 40 %
    # of a quick job; TensorBoard's pair plot of 2 parameters, not of 6 (36 panels drawn each round)
    quick = ["--rounds", "2", "--episodes", "2", "--overrides", *CPU_JOB, "debug=smoke", "logging.max_plot_params=2",
             "--rl-overrides", *CPU_JOB, "debug=smoke", "task.episode_length=100"]

    def __init__(self, name: str, tasks: dict[str, tuple[tuple[int, ...], tuple[int, ...], list[str]]],
                 needs_gpu: bool = False, priority: float = 0.0):
        self.name, self.needs_gpu, self.priority = name, needs_gpu, priority
        self.tasks = tasks  # per task: settings, seeds, and the script's further arguments (budgets, backends)

    def _studies(self, ctx: Context):
        for task, (settings, seeds, _) in self.tasks.items():
            yield task, (settings[:1], seeds[:1]) if ctx.quick else (settings, seeds)

    def _parts(self, ctx: Context):
        """Each job's task, name, settings, seeds and policies (None: all): per seed its baselines (first: two
        trainings without BayesSim before them), then its pairs; a GPU section's quick study in one job."""
        robots = script("rl_on_robots")
        for task, (settings, seeds) in self._studies(ctx):
            if ctx.quick and self.needs_gpu:  # a job fewer per task: each is a process importing torch
                yield task, task, settings, seeds, None
                continue
            for seed in seeds:
                yield task, f"{task}_baselines_seed{seed}", settings, [seed], robots.BASELINES
                for setting in settings:
                    yield task, f"{task}_setting{setting}_seed{seed}", [setting], [seed], robots.POSTERIORS

    def _argv(self, ctx: Context, task: str, settings, seeds, trained_on=None, out: Path | None = None) -> list[str]:
        return [sys.executable, "scripts/rl_on_robots.py", "--task", task, "--settings", *map(str, settings),
                "--seeds", *map(str, seeds), *(["--trained-on", *trained_on] if trained_on else []),
                *(self.quick if ctx.quick else self.tasks[task][2]), "--out", str(out or ctx.work / f"{task}.json"),
                "--run-dir", str(ctx.work / "runs")]

    def jobs(self, ctx: Context) -> list[Job]:
        baselines = script("rl_on_robots").BASELINES
        gpu = self.needs_gpu and not ctx.quick
        # a section's jobs start before those of a section of lower priority, a seed's baselines before its pairs
        return [Job(f"{self.name}/{name}", self._argv(ctx, task, settings, seeds, trained_on, ctx.work / f"{name}.json"),
                    self.priority + (400 if trained_on == baselines else 300), gpu=gpu)
                for task, name, settings, seeds, trained_on in self._parts(ctx)]

    def render(self, ctx: Context, stamp: str) -> str:
        robots = script("rl_on_robots")
        per_task: dict[str, dict] = {}
        for task, name, *_ in self._parts(ctx):
            part = json.loads((ctx.work / f"{name}.json").read_text())
            results = per_task.setdefault(task, {**part, "runs": []})
            results["runs"] = robots.merge(results["runs"], part["runs"])
        ctx.figures.mkdir(parents=True, exist_ok=True)
        blocks = []
        for task, results in per_task.items():
            (ctx.figures / f"rl_on_robots_{task}.json").write_text(json.dumps(results, indent=1))
            robots.plot(results, ctx.figures / f"rl_on_robots_{task}.png")
            blocks.append(self._task_block(ctx, task, results, robots.TRAINED_ON))
        return template(self.name).substitute(stamp=stamp, tasks="\n\n".join(blocks))

    def _task_block(self, ctx: Context, task: str, results: dict, trained_on: tuple[str, ...]) -> str:
        runs = results["runs"]
        score = {n: [r[n]["return"]["mean"] for r in runs] for n in trained_on}
        labels = {"posterior_round_1": "posterior after round 1", "posterior": f"posterior after round {results['rounds']}",
                  "prior": "uniform prior", "nominal": "nominal (the MJCF's)"}
        rows = [f"| {labels[n]} | {statistics.fmean(score[n]):.1f} | {_interval(score[n])} | "
                f"{_paired(score[n], score['prior'])} | {_paired(score[n], score['nominal'])} |" for n in trained_on]
        settings = sorted({r["setting"] for r in runs})
        seeds = sorted({r["seed"] for r in runs})
        by_setting = [f"setting {k} (" + ", ".join(f"{n} {v:.3g}" for n, v in next(
            r for r in runs if r["setting"] == k)["real"].items()) + "): " + ", ".join(
            f"{labels[n].split(' (')[0]} {statistics.fmean(r[n]['return']['mean'] for r in runs if r['setting'] == k):.1f}"
            for n in trained_on) for k in settings]
        ppo = runs[0]["ppo"]
        return "\n".join([
            f"### {task}", "",
            f"{len(settings)} surrogate real settings x {len(seeds)} seeds = {len(runs)} pairs; {results['rounds']} "
            f"BayesSim rounds per pair; PPO {ppo['steps']:,} steps on {ppo['envs']} environments per policy; each "
            f"score the mean return of {ppo['episodes']} surrogate real episodes of {ppo['episode_length']} steps. "
            "The whole study in one process (results.py runs it as one job per pair and one per seed for the "
            "uniform prior's and the nominal policies, which do not depend on the setting):", "",
            "```bash", python_command(self._argv(ctx, task, settings, seeds)), "```", "",
            "| trained on | mean score | 95 % interval of the mean | minus uniform prior, paired: mean [95 % interval] "
            "| minus nominal, paired |",
            "|---|---:|---:|---:|---:|", *rows, "",
            f"![{task}: score per pair and mean with its interval](figures/rl_on_robots_{task}.png)", "",
            "Per setting (mean over seeds): " + "; ".join(by_setting) + ".", "",
            _verdict_text(score, results["rounds"]), "",
            f"BayesSim took {spread([r['bayessim_seconds'] for r in runs], '.0f')} s per pair and each PPO run "
            f"{spread([r[n]['training']['seconds'] for r in runs for n in trained_on], '.0f')} s, with up to "
            f"{ctx.jobs} jobs sharing the machine. PPO's mean training return in its last batch (on the distribution "
            "it trained on), mean over the policies: " + ", ".join(
                f"{labels[n].split(' (')[0]} {_mean_finite(r[n]['training']['last_episode_return'] for r in runs)}"
                for n in trained_on) + f". Per pair: [figures/rl_on_robots_{task}.json](figures/rl_on_robots_{task}.json).",
        ])


@dataclasses.dataclass
class ScriptSection:
    """A script that prints its section's markdown, heading first, to stdout (its progress goes to stderr), and
    takes `--out DIR` for its runs."""

    name: str
    script: str                          # relative to the repository root
    args: tuple[str, ...] = ()           # the full budget
    quick_args: tuple[str, ...] = ()     # the tiny one
    cost: float = 300.0

    def jobs(self, ctx: Context) -> list[Job]:
        # its runs under the section's work dir, emptied before the jobs start: a run dir left by other code
        # (the script's default under /tmp) refuses to resume with another config
        argv = [sys.executable, self.script, *(self.quick_args if ctx.quick else self.args), "--out", str(ctx.work / "runs")]
        return [Job(self.name, argv, self.cost, stdout=ctx.work / "section.md")]

    def render(self, ctx: Context, stamp: str) -> str:
        lines = (ctx.work / "section.md").read_text().strip().splitlines()
        if not lines:
            raise SectionError(f"{self.script} printed nothing")
        command = f"`{python_command(self.jobs(ctx)[0].argv)}`: {stamp}"
        if lines[0].startswith("#"):
            return "\n".join([lines[0], "", command, *lines[1:]])
        return "\n".join([command, "", *lines])


def _sweep_values(value: str) -> list:
    if value.startswith("range("):
        return list(range(*map(int, value[len("range("):-1].split(","))))
    return value.split(",")


def _last(results: dict, key: str):
    return results["rounds"][-1][key]


def _width(results: dict, name: str) -> float:
    return results["prior"]["high"][name] - results["prior"]["low"][name]


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f}"


def _mean_finite(values) -> str:
    """The mean of the values that are numbers ("-" for none): a run whose episodes never ended has none."""
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return f"{statistics.fmean(finite):.1f}" if finite else "-"


def _verdict(k: int, n: int, level: float) -> str:
    """Where the share's 95 % interval leaves out the level: the regions are too narrow or too wide."""
    low, high = clopper_pearson(k, n)
    return " (too narrow)" if high < level else " (too wide)" if low > level else ""


def _interval(values: list[float]) -> str:
    """Student's t 95 % interval of the mean."""
    interval = script("rl_on_robots").t_interval(values)
    return "-" if interval is None else f"[{interval[0]:.1f}, {interval[1]:.1f}]"


def _paired(values: list[float], baseline: list[float]) -> str:
    if values is baseline:
        return "-"
    diff = [a - b for a, b in zip(values, baseline)]
    return f"{statistics.fmean(diff):+.1f} {_interval(diff)}"


def _verdict_text(score: dict[str, list[float]], rounds: int) -> str:
    """Where the last round's posterior helps and where it does not, from the paired intervals."""
    t_interval = script("rl_on_robots").t_interval
    parts = []
    for baseline, label in (("prior", "uniform randomization"), ("nominal", "the nominal model"),
                            ("posterior_round_1", "round 1's posterior")):
        diff = [a - b for a, b in zip(score["posterior"], score[baseline])]
        interval = t_interval(diff)
        mean = statistics.fmean(diff)
        if interval is None or interval[0] == interval[1]:
            parts.append(f"against {label}: no spread to test")
        elif interval[0] > 0:
            parts.append(f"better than {label} (paired difference {mean:+.1f}, interval above zero)")
        elif interval[1] < 0:
            parts.append(f"**worse** than {label} (paired difference {mean:+.1f}, interval below zero)")
        else:
            parts.append(f"not distinguishable from {label} (paired difference {mean:+.1f}, interval across zero)")
    return f"The round-{rounds} posterior's policy is " + "; ".join(parts) + "."

"""docs/results.md from its experiments: every section's jobs in parallel processes, then each section's markdown.

    python benchmarks/results.py --jobs 14            # make results: the full budgets, docs/results.md + docs/figures/
    python benchmarks/results.py --quick --jobs 2     # tiny budgets into outputs/results_quick/ (never docs/)
    python benchmarks/results.py --sections methods   # only these sections; the others keep their current text
    python benchmarks/results.py --resume             # a killed call's jobs go on from what they finished
    python benchmarks/results.py --render-only        # render what a call left in outputs/results, as it stamped it

Sections that train on a GPU (`needs_gpu`: the robots' PPO on MuJoCo Warp) are skipped, their text kept, where
nvidia-smi lists no GPU; their jobs share the GPUs (`--gpus`, `--per-gpu` at once on each, CUDA_VISIBLE_DEVICES).

Measured: the methods section's 139 jobs (18 at the tasks' truths, 120 known-truth runs, one closed loop), 2 at a
time on the 2-core development machine, in 1,979 s (2026-11-25; 3,957 s of jobs, the longest 71 s); on the lent
H100 machine's 16 cores (2026-11-23) the PPO section's 3 jobs with the methods section's 13 of then, 15 at a
time, in 144 s (the longest, a PPO seed, 144 s; docs/results.md stamps each); the foreign-dynamics section (59 whole
runs in its own pool) took 282 s with its fits on the GPU (`--device cuda`) and is estimated at two to three
times that with CPU fits, its default here; the robots section's 15 Cartpole jobs (BayesSim, then four PPO
policies each), 2 at a time on the development machine, in 588 s (2026-11-26; 1,111 s of jobs, the longest 78 s),
and in 480 s once the prior's and nominal policies were trained once per seed; the GPU sections' 40 Ant and
Humanoid jobs, 16 at a time on 4 H100s (4 per GPU), in 1,368 s (2026-11-26; 18,523 s of jobs, the longest 715 s).
Every methods and PPO job runs on one CPU thread (`sim=native device=cpu`), so that a dozen processes do not share
the GPU; the GPU sections' jobs run BayesSim so and PPO on their GPU. `--sections` runs sections in separate calls
where one call's time is short.

SECTIONS below is the order of docs/results.md; each section (benchmarks/results_sections.py) declares its jobs
and renders its markdown, stamped with its commands, the commit ($COMMIT where set, as for a copy sent to
another machine, else `git rev-parse --short HEAD`), the machine (host, CPU model and cores, GPU) and the UTC
date. A section lives between
`<!-- section NAME -->` and `<!-- end NAME -->` in the output, which is how --sections keeps the others.
Runs and logs go to outputs/results/ (quick: outputs/results_quick/), emptied per section at its start.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import queue
import re
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from results_sections import (
    CPU_JOB,
    GPU_PPO,
    ROOT,
    TEMPLATES,
    Context,
    Job,
    MethodsSection,
    RlSection,
    RobotsSection,
    ScriptSection,
)

ROBOTS_ON_GPU = ["--overrides", *CPU_JOB, "--rl-overrides", *GPU_PPO, "rl.train.total_steps=16777216"]
SECTIONS = [
    MethodsSection(),
    # its own process pool of 12 runs (one thread each; `--device cuda` fits on a GPU where there is one)
    ScriptSection("foreign_dynamics", "benchmarks/foreign_dynamics.py", args=("--section", "--jobs", "12"),
                  # one worker: results.py's jobs already fill the cores; one round of smoke's simulations, not
                  # --quick's 2 of 2,000 (the section reads the last round)
                  quick_args=("--section", "--quick", "--jobs", "1", "--sources", "ours", "--settings", "1",
                              "--sine", "0", "--overrides", "debug=smoke", "rounds=1", "collect.trajectories=300"),
                  cost=600.0),
    RlSection(),
    # per task: surrogate real settings, seeds, scripts/rl_on_robots.py's budget and backends
    RobotsSection("rl_on_robots", {"Cartpole": ((0, 1, 2), (0, 1, 2, 3, 4),
                                                ["--overrides", *CPU_JOB, "--rl-overrides", *CPU_JOB])}),
    # BayesSim on one CPU thread, PPO on a GPU (MuJoCo Warp) for the budget of Ant's learning curve
    # (docs/benchmarks.md); Ant's jobs start before Humanoid's
    RobotsSection("rl_on_robots_gpu", {"Ant": ((0, 1, 2), (0, 1, 2, 3, 4), ROBOTS_ON_GPU)}, needs_gpu=True,
                  priority=1000.0),
    RobotsSection("rl_on_robots_humanoid", {"Humanoid": ((0, 1, 2), (0, 1, 2, 3, 4), ROBOTS_ON_GPU)}, needs_gpu=True),
]
BLOCK = re.compile(r"<!-- section (\S+) -->\n(.*?)\n<!-- end \1 -->", re.S)


def commit() -> str:
    if os.environ.get("COMMIT"):  # a copy sent to another machine: its .git, where it has one, is not what was sent
        return os.environ["COMMIT"]
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True,
                               text=True, check=True).stdout.strip()
        return sha + (" with uncommitted changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return os.environ.get("COMMIT", "unknown (no .git here and no $COMMIT)")


def machine() -> str:
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), "unknown CPU") if Path("/proc/cpuinfo").exists() else "unknown CPU"
    try:
        gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, check=True).stdout.strip().replace("\n", ", ") or "no GPU"
    except (OSError, subprocess.CalledProcessError):
        gpu = "no GPU"
    versions = ", ".join(f"{name} {metadata.version(name)}" for name in ("torch", "mujoco"))
    return f"{socket.gethostname()} ({os.cpu_count()} x {cpu}; {gpu}; {versions})"


def visible_gpus() -> list[str]:
    """The indices nvidia-smi lists (none without it)."""
    try:
        listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return [str(i) for i, line in enumerate(listed.splitlines()) if line.startswith("GPU ")]


def run_jobs(jobs: list[Job], parallel: int, logs: Path, gpu_slots: list[str],
             finished: Callable[[Job, float], None]) -> dict[str, float | None]:
    """Each job's wall seconds, None where it failed (its log's tail printed); the longest-estimated start first.
    A GPU job waits for one of `gpu_slots` (a GPU index per job it may run at once) and sees only that GPU.
    `finished(job, seconds)` is called as each job succeeds."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "src"), os.environ.get("PYTHONPATH")]))}
    free = queue.SimpleQueue()
    for slot in gpu_slots:
        free.put(slot)

    def one(job: Job) -> float | None:
        log = logs / f"{job.name}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        if job.stdout:
            job.stdout.parent.mkdir(parents=True, exist_ok=True)
        gpu = free.get() if job.gpu and gpu_slots else None
        start = time.perf_counter()
        try:
            with open(log, "w") as err, open(job.stdout or os.devnull, "w") as out:
                done = subprocess.run(job.argv, cwd=ROOT, env=env if gpu is None else {**env, "CUDA_VISIBLE_DEVICES": gpu},
                                      stdout=out if job.stdout else err, stderr=err)
        finally:
            if gpu is not None:
                free.put(gpu)
        seconds = time.perf_counter() - start
        if done.returncode == 0:
            print(f"  {job.name}: {seconds:.0f} s", flush=True)
            finished(job, seconds)
            return seconds
        tail = "\n    ".join(log.read_text().splitlines()[-15:])
        print(f"  {job.name}: FAILED ({done.returncode}) after {seconds:.0f} s, log {log}:\n    {tail}", flush=True)
        return None

    with ThreadPoolExecutor(max(1, parallel)) as pool:
        ordered = sorted(jobs, key=lambda j: -j.cost)
        return dict(zip((j.name for j in ordered), pool.map(one, ordered)))


def assemble(previous: str, fresh: dict[str, str]) -> str:
    """The header, then every section in SECTIONS' order: fresh text, else the previous text, else a placeholder."""
    kept = {name: body for name, body in BLOCK.findall(previous)}
    parts = [(TEMPLATES / "header.md").read_text().strip()]
    for section in SECTIONS:
        body = fresh.get(section.name) or kept.get(section.name) or (
            f"_Not generated yet: `python benchmarks/results.py --sections {section.name}`._")
        parts.append(f"<!-- section {section.name} -->\n{body.strip()}\n<!-- end {section.name} -->")
    return "\n\n".join(parts) + "\n"


class Record:
    """What a call ran, in each section's work dir (generated.json): the line that stamps the section and each
    finished job's seconds, written as jobs finish, so that `--render-only` renders what a killed call left."""

    def __init__(self, work: Path):
        self.path, self.lock = work / "generated.json", threading.Lock()

    def start(self, line: str, stamp: str, jobs: int, resume: bool) -> None:
        """A fresh record, or with `resume` the earlier call's, its line noting this call's stamp."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if resume and self.path.exists():
            record = self.read()
            record["line"] += f"; resumed {stamp}"
        else:
            record = {"line": f"{line}, {stamp}", "jobs": jobs, "seconds": {}}
        self.path.write_text(json.dumps(record, indent=1))

    def finished(self, job: Job, seconds: float) -> None:
        """A job's seconds, unless an earlier call measured it (a resumed job skips what it finished)."""
        with self.lock:
            record = self.read()
            record["seconds"].setdefault(job.name, seconds)
            self.path.write_text(json.dumps(record, indent=1))

    def read(self) -> dict:
        if not self.path.exists():
            raise SystemExit(f"{self.path} is missing: no call of results.py ran this section in this work dir")
        return json.loads(self.path.read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 2) - 2), help="processes at a time")
    ap.add_argument("--quick", action="store_true", help="tiny budgets, output outside docs/")
    ap.add_argument("--sections", nargs="+", choices=[s.name for s in SECTIONS], help="default: all")
    ap.add_argument("--out", type=Path, help="the markdown written (default: docs/results.md; quick: "
                                             "outputs/results_quick/results.md); figures go to figures/ beside it")
    ap.add_argument("--work", type=Path, help="runs and logs (default: outputs/results or outputs/results_quick)")
    ap.add_argument("--gpus", nargs="*", help="GPU indices the GPU jobs share (default: all nvidia-smi lists)")
    ap.add_argument("--per-gpu", type=int, default=4, help="GPU jobs at once per GPU (a job's BayesSim part uses "
                                                           "only a CPU thread, its PPO the GPU)")
    ap.add_argument("--render-only", action="store_true", help="run no job: render the sections from what an "
                    "earlier call (killed, or on another machine) left in the work dir, stamped as that call")
    ap.add_argument("--resume", action="store_true", help="keep the work dir: jobs skip what an earlier call "
                    "finished (the sections' scripts resume), and the stamp names both calls")
    args = ap.parse_args()
    gpus = visible_gpus() if args.gpus is None else args.gpus
    out = args.out or ROOT / ("outputs/results_quick/results.md" if args.quick else "docs/results.md")
    if args.quick and out.resolve().is_relative_to((ROOT / "docs").resolve()):
        raise SystemExit("--quick writes outside docs/: its numbers are no results")
    work = args.work or ROOT / ("outputs/results_quick" if args.quick else "outputs/results")
    chosen = [s for s in SECTIONS if s.name in args.sections] if args.sections else [
        s for s in SECTIONS if args.quick or args.render_only or gpus or not getattr(s, "needs_gpu", False)]
    for section in SECTIONS:
        if section not in chosen and not args.sections:
            print(f"{section.name}: skipped, it trains on a GPU and none is visible (its previous text kept)")
    ctx = {s.name: Context(work=work / s.name, figures=out.parent / "figures", quick=args.quick, jobs=args.jobs)
           for s in chosen}
    records = {s.name: Record(ctx[s.name].work) for s in chosen}
    if args.render_only:  # the text quotes the processes at a time of the call that ran the jobs
        ctx = {name: dataclasses.replace(c, jobs=records[name].read()["jobs"]) for name, c in ctx.items()}
    jobs = {s.name: s.jobs(ctx[s.name]) for s in chosen}
    if not args.render_only:
        stamp = f"commit {commit()}, {machine()}, {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
        mode = " --quick" if args.quick else ""
        for section in chosen:
            if not args.resume:
                shutil.rmtree(ctx[section.name].work, ignore_errors=True)
            on_gpus = any(j.gpu for j in jobs[section.name]) and gpus
            sharing = f" --per-gpu {args.per_gpu}" if on_gpus else ""
            records[section.name].start(f"Generated by `python benchmarks/results.py{mode} --jobs {args.jobs}{sharing} "
                                        f"--sections {section.name}`{f' ({len(gpus)} GPUs)' if on_gpus else ''}",
                                        stamp, args.jobs, args.resume)
        print(f"{sum(map(len, jobs.values()))} jobs, {args.jobs} at a time; logs in {work / 'logs'}", flush=True)
        start = time.perf_counter()
        run_jobs([j for js in jobs.values() for j in js], args.jobs, work / "logs",
                 [gpu for _ in range(args.per_gpu) for gpu in gpus],
                 lambda job, seconds: records[job.name.split("/")[0]].finished(job, seconds))
        print(f"jobs done in {time.perf_counter() - start:.0f} s", flush=True)

    fresh, failed = {}, []
    for section in chosen:
        record = records[section.name].read()
        took = [record["seconds"][j.name] for j in jobs[section.name] if j.name in record["seconds"]]
        if len(took) < len(jobs[section.name]):
            print(f"{section.name}: {len(took)} of {len(jobs[section.name])} jobs finished; not rendered", flush=True)
            failed.append(section.name)
            continue
        rendered = f"; rendered by --render-only at commit {commit()}" if args.render_only else ""
        line = f"{record['line']}; its jobs ran {max(took, default=0):.0f} s at most, {sum(took):.0f} s in all{rendered}."
        try:
            fresh[section.name] = section.render(ctx[section.name], line)
        except Exception as exc:  # a section that cannot render keeps its previous text; the others are written
            print(f"{section.name}: not rendered: {type(exc).__name__}: {exc}", flush=True)
            failed.append(section.name)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(assemble(out.read_text() if out.exists() else "", fresh))
    print(f"wrote {out} ({', '.join(fresh) or 'no section'} regenerated)")
    if failed:
        raise SystemExit(f"failed: {', '.join(failed)} (their previous text kept)")


if __name__ == "__main__":
    main()

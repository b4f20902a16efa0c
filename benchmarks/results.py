"""docs/results.md from its experiments: every section's jobs in parallel processes, then each section's markdown.

    python benchmarks/results.py --jobs 14            # make results: the full budgets, docs/results.md + docs/figures/
    python benchmarks/results.py --quick --jobs 2     # tiny budgets into outputs/results_quick/ (never docs/)
    python benchmarks/results.py --sections methods   # only these sections; the others keep their current text

Measured: the methods section's 139 jobs (18 at the tasks' truths, 120 known-truth runs, one closed loop), 2 at a
time on the 2-core development machine, in 1,979 s (2026-11-25; 3,957 s of jobs, the longest 71 s); on the lent
H100 machine's 16 cores (2026-11-23) the PPO section's 3 jobs with the methods section's 13 of then, 15 at a
time, in 144 s (the longest, a PPO seed, 144 s; docs/results.md stamps each); the foreign-dynamics section (59 whole
runs in its own pool) took 282 s with its fits on the GPU (`--device cuda`) and is estimated at two to three
times that with CPU fits, its default here; the robots section's 15 Cartpole jobs (BayesSim, then four PPO
policies each), 2 at a time on the development machine, in 588 s (2026-11-26; 1,111 s of jobs, the longest 78 s). Every methods and PPO job runs on one CPU thread (`sim=native
device=cpu`), so that a dozen processes do not share the GPU. `--sections` runs sections in separate calls
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
import os
import re
import shutil
import socket
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from results_sections import ROOT, TEMPLATES, Context, Job, MethodsSection, RlSection, RobotsSection, ScriptSection

SECTIONS = [
    MethodsSection(),
    # its own process pool of 12 runs (one thread each; `--device cuda` fits on a GPU where there is one)
    ScriptSection("foreign_dynamics", "benchmarks/foreign_dynamics.py", args=("--section", "--jobs", "12"),
                  quick_args=("--section", "--quick", "--jobs", "2", "--sources", "ours", "--settings", "1",
                              "--sine", "0"), cost=600.0),
    RlSection(),
    RobotsSection(),
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


def run_jobs(jobs: list[Job], parallel: int, logs: Path) -> dict[str, float | None]:
    """Each job's wall seconds, None where it failed (its log's tail printed); the longest-estimated start first."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "src"), os.environ.get("PYTHONPATH")]))}

    def one(job: Job) -> float | None:
        log = logs / f"{job.name}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        if job.stdout:
            job.stdout.parent.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        with open(log, "w") as err, open(job.stdout or os.devnull, "w") as out:
            done = subprocess.run(job.argv, cwd=ROOT, env=env, stdout=out if job.stdout else err, stderr=err)
        seconds = time.perf_counter() - start
        if done.returncode == 0:
            print(f"  {job.name}: {seconds:.0f} s", flush=True)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 2) - 2), help="processes at a time")
    ap.add_argument("--quick", action="store_true", help="tiny budgets, output outside docs/")
    ap.add_argument("--sections", nargs="+", choices=[s.name for s in SECTIONS], help="default: all")
    ap.add_argument("--out", type=Path, help="the markdown written (default: docs/results.md; quick: "
                                             "outputs/results_quick/results.md); figures go to figures/ beside it")
    ap.add_argument("--work", type=Path, help="runs and logs (default: outputs/results or outputs/results_quick)")
    args = ap.parse_args()
    out = args.out or ROOT / ("outputs/results_quick/results.md" if args.quick else "docs/results.md")
    if args.quick and out.resolve().is_relative_to((ROOT / "docs").resolve()):
        raise SystemExit("--quick writes outside docs/: its numbers are no results")
    work = args.work or ROOT / ("outputs/results_quick" if args.quick else "outputs/results")
    chosen = [s for s in SECTIONS if not args.sections or s.name in args.sections]
    stamp = f"commit {commit()}, {machine()}, {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
    ctx = {s.name: Context(work=work / s.name, figures=out.parent / "figures", quick=args.quick, jobs=args.jobs)
           for s in chosen}
    for section in chosen:
        shutil.rmtree(ctx[section.name].work, ignore_errors=True)
    jobs = {s.name: s.jobs(ctx[s.name]) for s in chosen}
    print(f"{sum(map(len, jobs.values()))} jobs, {args.jobs} at a time; logs in {work / 'logs'}", flush=True)
    start = time.perf_counter()
    seconds = run_jobs([j for js in jobs.values() for j in js], args.jobs, work / "logs")
    print(f"jobs done in {time.perf_counter() - start:.0f} s", flush=True)

    fresh, failed = {}, []
    for section in chosen:
        took = [seconds[j.name] for j in jobs[section.name]]
        if None in took:
            failed.append(section.name)
            continue
        mode = " --quick" if args.quick else ""
        line = (f"Generated by `python benchmarks/results.py{mode} --jobs {args.jobs} --sections {section.name}`, "
                f"{stamp}; its jobs ran {max(took, default=0):.0f} s at most, {sum(took):.0f} s in all.")
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

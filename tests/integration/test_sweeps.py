"""Sweeps through the real CLI: a --multirun sweep and its report, a job killed while fitting that
resumes to the same results, and a researcher's own summarizer swept over with the built-in ones."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bayessim_exp.artifacts import RunDir
from bayessim_exp.report.build import build_report
from bayessim_exp.testing.run_results import without_seconds

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}


def cli(*args, cwd, timeout=600, preexec_fn=None):
    return subprocess.run([sys.executable, "-m", "bayessim_exp", *args], cwd=cwd, env=ENV, capture_output=True,
                          text=True, timeout=timeout, preexec_fn=preexec_fn)


def every_cpu() -> None:
    """In the child: every CPU of the machine, not the pinned test worker's one (a run on one CPU draws its figures
    in its own process, logging/tensorboard.py)."""
    os.sched_setaffinity(0, range(os.cpu_count()))




def test_jobs_of_the_local_launcher_finish_with_their_figures(tmp_path):
    """hydra/launcher=local runs jobs in joblib (loky) workers, whose start method a process they spawn cannot
    set up: the figures' drawing process must start anyway (every such job used to fail)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    if not hasattr(os, "sched_setaffinity") or os.cpu_count() < 2:
        pytest.skip("a drawing process starts only where a run may use two CPUs or more")
    sweep = tmp_path / "sweep"
    proc = cli("--multirun", "seed=0,1", "debug=smoke", "hydra/launcher=local",
               f"hydra.sweep.dir={sweep}", cwd=tmp_path, preexec_fn=every_cpu)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for job in sorted(sweep.glob("*_seed*")):
        assert (job / "results.json").is_file() and not (job / "error.txt").exists()
        events = EventAccumulator(str(job), size_guidance={"images": 0}).Reload()
        assert len(events.Images("posterior")) == 2, job


def test_a_multirun_sweep_and_its_report(tmp_path):
    """Seeds at the task's own truth and seeds at truths drawn from the prior: only the latter get a calibration
    section, with KS numbers; the sweep's end prints the report command and leaves TensorBoard hparams per job."""
    sweep = tmp_path / "sweep"
    proc = cli("--multirun", "real.truth=task,prior", "seed=0,1", "debug=smoke", f"hydra.sweep.dir={sweep}",
               cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert f"python -m bayessim_exp.report {sweep}" in proc.stdout.splitlines()[-1]
    assert len(list(sweep.glob("*_seed*/events.out.tfevents.*.hparams"))) == 4
    report = subprocess.run([sys.executable, "-m", "bayessim_exp.report", str(sweep)], env=ENV, capture_output=True,
                            text=True, timeout=300)
    assert report.returncode == 0, report.stderr[-3000:]
    assert "4 jobs: 4 finished, 0 failed, 0 unfinished" in report.stdout
    markdown = (sweep / "report" / "report.md").read_text()
    assert re.search(r"^\| real.truth=task \| 2 \| .+ \|$", markdown, re.M)
    assert re.search(r"^\| real.truth=prior \| 2 \| .+ \|$", markdown, re.M)
    assert "`real.truth=task`: 2 job(s) at one truth (real.truth=task): no calibration section" in markdown
    calibration = markdown[markdown.index("## Calibration"):]
    assert "### `real.truth=prior`" in calibration and "real.truth=task" not in calibration
    assert re.search(r"^\| mass \| [0-9.e-]+ \| – \|$", calibration, re.M)  # KS; C2ST needs 10 truths
    pngs = sorted(p.name for p in (sweep / "report").glob("*.png"))
    assert {"log_prob_gain.png", "gain_by_round.png", "posterior_00.png", "posterior_01.png", "sbc_ranks_00.png"} <= set(pngs)
    rows = (sweep / "report" / "jobs.csv").read_text().splitlines()
    assert len(rows) == 5 and all(",finished," in row for row in rows[1:])


def test_a_job_killed_while_fitting_resumes_and_matches_a_run_never_killed(tmp_path):
    args = ["debug=smoke", "seed=3"]
    reference = cli(*args, f"hydra.run.dir={tmp_path}/reference", cwd=tmp_path)
    assert reference.returncode == 0, reference.stderr[-3000:]

    run_dir = tmp_path / "killed"
    summarized = run_dir / "round_001" / "summarize.pt"
    proc = subprocess.Popen([sys.executable, "-m", "bayessim_exp", *args, f"hydra.run.dir={run_dir}"], cwd=tmp_path,
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while not summarized.exists():  # the next stage, fit, starts right after this file is written
        assert proc.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline, "round 1 was never summarized"
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (run_dir / "round_001" / "fit.pt").exists(), "killed too late: round 1's fit had finished"
    assert not (run_dir / "results.json").exists()
    finished = {p: p.stat().st_mtime_ns for p in run_dir.glob("round_*/*.pt")}

    resumed = cli(*args, f"hydra.run.dir={run_dir}", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "round 1: summarize done" not in resumed.stderr + resumed.stdout  # not redone
    # finished artifacts untouched, but for the transient collect.pt, which shrinks to its timing once summarized,
    # round 1's too although its summarize stage was not rerun
    assert all(p.stat().st_mtime_ns == t for p, t in finished.items() if p.name != "collect.pt")
    assert all(set(RunDir(run_dir).load(r, "collect")) == {"seconds"} for r in (1, 2))
    expected = json.loads((tmp_path / "reference" / "results.json").read_text())
    got = json.loads((run_dir / "results.json").read_text())
    assert len(got["rounds"]) == 2
    assert without_seconds(got) == without_seconds(expected)


def readme_extension_example() -> tuple[dict[str, str], list[str]]:
    """The files (first line `# <path>`) and the commands of README's "Your own components"."""
    text = (REPO / "README.md").read_text()
    section = text.split("**Your own components.**", 1)[1].split("\n## ", 1)[0]
    files, commands = {}, []
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", section, re.S):
        if lang == "bash":
            commands += [line for line in body.splitlines() if line.startswith("python -m bayessim_exp")]
        else:
            first, _, _ = body.partition("\n")
            files[first.lstrip("# ").strip()] = body
    return files, commands


def test_the_readme_extension_example_sweeps_an_outside_summarizer_with_built_in_ones(tmp_path):
    files, commands = readme_extension_example()
    assert {"mylab/summaries.py", "mylab/conf/summarizer/final.yaml"} <= set(files)
    for path, body in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(body)
    sweeps = [c for c in commands if "--multirun" in c]
    assert len(sweeps) == 1, commands
    import shlex

    argv = [a for a in shlex.split(sweeps[0])[3:] if not a.startswith("seed=")]  # one seed is enough here
    sweep = tmp_path / "sweep"
    proc = cli(*argv, "debug=smoke", "seed=0", f"hydra.sweep.dir={sweep}", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = build_report(sweep, posteriors=False)
    summarizers = sorted(j.results["summarizer"] for j in report.jobs if j.status == "finished")
    assert summarizers == ["final", "start", "waypoints"]
    assert "| summarizer=final | 1 |" in (sweep / "report" / "report.md").read_text()

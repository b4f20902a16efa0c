"""A real Slurm (one node on localhost, scripts/slurm_localhost.sh): a sweep through the submitit
launcher end to end, one job preempted while fitting, requeued, and finishing with the results of a
run never preempted. Runs where Slurm already runs (`scripts/slurm_localhost.sh status`), or where the caller
opts in with BAYESSIM_SLURM_TEST=1 (.ci/run does): the script then installs and starts Slurm (root, apt). Skipped,
with the reason, otherwise: a test suite must not install or start system software unasked."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bayessim_exp.testing.run_results import without_seconds

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "scripts" / "slurm_localhost.sh"
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}
# one CPU per job so that both jobs of the sweep run at once on a 2-core node
LAUNCHER = ["hydra/launcher=slurm_cpu", "hydra.launcher.partition=debug", "hydra.launcher.cpus_per_task=1",
            "hydra.launcher.mem_gb=1", "hydra.launcher.timeout_min=15"]
RUN = ["debug=smoke"]
OPT_IN = "BAYESSIM_SLURM_TEST"  # lets the test install and start Slurm where none runs


@pytest.fixture(scope="module")
def slurm():
    """A running one-node Slurm; started only on opt-in, stopped afterwards only if this fixture started it."""
    if subprocess.run(["bash", str(SCRIPT), "status"], capture_output=True).returncode == 0:
        yield
        return
    if os.environ.get(OPT_IN) != "1":
        pytest.skip(f"no Slurm runs here (scripts/slurm_localhost.sh status); {OPT_IN}=1 lets this test install "
                    "and start a one-node Slurm (root, Debian)")
    proc = subprocess.run(["bash", str(SCRIPT), "start"], capture_output=True, text=True, timeout=900)
    if proc.returncode != 0:
        reason = (proc.stderr.strip().splitlines() or ["no reason given"])[-1]
        pytest.skip(f"Slurm cannot start here: {reason}")
    yield
    subprocess.run(["bash", str(SCRIPT), "stop"], capture_output=True, timeout=60)


def wait_for(condition, what, proc, timeout=300):
    deadline = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, f"the sweep ended before {what}: {proc.communicate()[1][-3000:]}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_a_sweep_on_slurm_with_a_preempted_job_that_resumes(slurm, tmp_path):
    # a timestamped sweep dir, as the stored sweeps have: the requeued job must come back to the same one
    root = tmp_path / "sweeps"
    proc = subprocess.Popen([sys.executable, "-m", "bayessim_exp", "--multirun", *LAUNCHER, *RUN, "seed=0,1",
                             f"hydra.sweep.dir={root}/${{now:%H-%M-%S-%f}}"], cwd=tmp_path, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    job_ids: list[str] = []
    try:
        summarized = lambda: list(root.glob("*/0_*/round_001/summarize.pt"))  # noqa: E731
        wait_for(summarized, "job 0 to reach fitting", proc)
        sweep = summarized()[0].parents[2]
        job_ids = sorted(p.name for p in (sweep / ".submitit").iterdir() if p.name[0].isdigit())
        preempted = next(j for j in job_ids if j.endswith("_0"))
        stamp = summarized()[0].stat().st_mtime_ns
        # what Slurm does on preemption, as submitit's own tests do: TERM (ignored), then USR2 (checkpoint, requeue)
        subprocess.run(["scancel", "--signal=TERM", preempted], check=True)
        subprocess.run(["scancel", "--signal=USR2", preempted], check=True)
        out, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            for job in job_ids:
                subprocess.run(["scancel", job], capture_output=True)
    assert proc.returncode == 0, err[-3000:]
    logs = "".join(p.read_text() for p in (sweep / ".submitit" / preempted).glob("*_log.*"))
    assert "this job is preempted" in logs and f"Requeued job {preempted}" in logs, logs[-3000:]
    assert [p.name for p in root.iterdir()] == [sweep.name]
    job0 = next(sweep.glob("0_*"))
    assert summarized()[0].stat().st_mtime_ns == stamp  # the finished stage survived the requeue untouched

    reference = subprocess.run([sys.executable, "-m", "bayessim_exp", *RUN, "seed=0", f"hydra.run.dir={tmp_path}/ref"],
                               cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=300)
    assert reference.returncode == 0, reference.stderr[-3000:]
    got = json.loads((job0 / "results.json").read_text())
    assert without_seconds(got) == without_seconds(json.loads((tmp_path / "ref" / "results.json").read_text()))
    seed1 = json.loads(next(sweep.glob("1_*/results.json")).read_text())
    assert seed1["seed"] == 1 and len(seed1["rounds"]) == len(got["rounds"]) == 2

"""The README's Python API snippet, verbatim, as a user's script without a main guard (issue 46): a spawned drawing
process would import the script again and run it again; api.run draws its figures in its own process instead."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from bayessim_exp import api

ROOT = Path(__file__).resolve().parents[2]
# what the snippet leaves to its reader: pairs of a prior's draws and their summaries, one observed summary
DATA = """import torch
low, high = torch.tensor([0.5, 0.25]), torch.tensor([2.0, 1.0])
theta = low + (high - low) * torch.rand(2000, 2, generator=torch.Generator().manual_seed(0))
x = torch.cat([theta, theta.prod(1, keepdim=True)], 1) + 0.05 * torch.randn(2000, 3, generator=torch.Generator().manual_seed(1))
x_obs = x[0]
"""


def readme_snippet() -> str:
    section = (ROOT / "README.md").read_text().split("## Python API", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_api_snippet_runs_as_a_script_without_a_main_guard_and_draws_every_figure(tmp_path):
    script = tmp_path / "try_api.py"
    script.write_text(DATA + readme_snippet())
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "bootstrapping" not in done.stderr and "could not be drawn" not in done.stderr, done.stderr[-3000:]
    run_dir = tmp_path / "outputs" / "try"
    events = list(run_dir.glob("events.out.tfevents.*"))
    assert len(events) == 1, events  # the script ran once: no second run into the same directory
    accumulator = EventAccumulator(str(events[0]), size_guidance={"images": 0})
    accumulator.Reload()
    rounds = len(api.load_run(run_dir).results["rounds"])
    assert [e.step for e in accumulator.Images("posterior")] == list(range(1, rounds + 1))
    assert "identifiability" in accumulator.Tags()["images"]


def test_a_runs_posterior_is_asked_for_by_its_round_number(tmp_path):
    """Round numbers start at 1; 0 or a round the run never reached is refused, not read as the last round."""
    api.run(["task=Pendulum", "debug=smoke", "logging.progress=false"], out_dir=tmp_path)
    run = api.load_run(tmp_path)
    theta = torch.tensor([[1.0, 0.5]], dtype=torch.float64)
    last = run.posterior()
    torch.testing.assert_close(last.log_prob(theta), run.posterior(len(run.results["rounds"])).log_prob(theta))
    for wrong in (0, len(run.results["rounds"]) + 1):
        with pytest.raises(ValueError, match=f"round_index={wrong}: this run finished rounds 1 to"):
            run.posterior(wrong)

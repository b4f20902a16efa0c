"""Restructurings keep behaviour: a Pendulum smoke run's results.json matches the one recorded in golden/ (wall
times aside). Floats are compared to a relative 1e-6, the room that another CPU's vector instructions take.

After a change that is meant to alter results, record the new reference and say why in the commit:
    python tests/integration/test_golden_results.py
"""

import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from run_results import without_seconds  # noqa: E402

pytestmark = pytest.mark.slow

GOLDEN = Path(__file__).parent / "golden"
# name -> overrides; the test keeps the first, the others are checked by hand around a restructuring
RUNS = {
    "pendulum_smoke": ["task=Pendulum", "debug=smoke"],
    "cartpole_smoke": ["task=Cartpole", "debug=smoke"],
    "ant_smoke": ["task=Ant", "debug=smoke"],
    "pendulum_default": ["task=Pendulum"],
}


def differences(got, want, path="results"):
    """Every place where got and want differ beyond the float tolerance, as readable lines."""
    if isinstance(want, dict) and isinstance(got, dict):
        keys = set(got) | set(want)
        return [d for k in sorted(keys, key=str) for d in (
            differences(got[k], want[k], f"{path}.{k}") if k in got and k in want else [f"{path}.{k}: only in one"])]
    if isinstance(want, list) and isinstance(got, list) and len(got) == len(want):
        return [d for i, (g, w) in enumerate(zip(got, want)) for d in differences(g, w, f"{path}[{i}]")]
    if isinstance(want, float) and isinstance(got, (int, float)) and not isinstance(got, bool):
        same = math.isclose(got, want, rel_tol=1e-6, abs_tol=1e-9) or (math.isnan(got) and math.isnan(want))
        return [] if same else [f"{path}: {got!r} (recorded {want!r})"]
    return [] if got == want else [f"{path}: {got!r} (recorded {want!r})"]


def run(name, out_dir):
    from bayessim_exp.api import compose
    from bayessim_exp.pipeline import Pipeline

    Pipeline(compose(RUNS[name]), out_dir).run()
    return without_seconds(json.loads((out_dir / "results.json").read_text()))


def test_a_pendulum_smoke_run_matches_its_recorded_results(tmp_path):
    want = json.loads((GOLDEN / "pendulum_smoke.json").read_text())
    assert differences(run("pendulum_smoke", tmp_path), want) == []


def test_the_comparison_sees_a_changed_number():
    want = {"rounds": [{"log_prob_gain": 1.5, "proposal": "prior"}]}
    assert differences({"rounds": [{"log_prob_gain": 1.5 * (1 + 1e-7), "proposal": "prior"}]}, want) == []
    assert differences({"rounds": [{"log_prob_gain": 1.501, "proposal": "prior"}]}, want) == [
        "results.rounds[0].log_prob_gain: 1.501 (recorded 1.5)"]
    assert differences({"rounds": [{"log_prob_gain": 1.5, "proposal": "truncated"}]}, want) == [
        "results.rounds[0].proposal: 'truncated' (recorded 'prior')"]


if __name__ == "__main__":  # record (or, with --check, compare) every reference run
    import tempfile

    check = "--check" in sys.argv
    for name in [a for a in sys.argv[1:] if not a.startswith("--")] or RUNS:
        with tempfile.TemporaryDirectory() as tmp:
            got = run(name, Path(tmp))
        if check:
            found = differences(got, json.loads((GOLDEN / f"{name}.json").read_text()))
            print(f"{name}: {'same' if not found else chr(10).join(found[:20])}")
        else:
            (GOLDEN / f"{name}.json").write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
            print(f"recorded {GOLDEN / name}.json")

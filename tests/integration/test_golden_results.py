"""Restructurings keep behaviour: a Pendulum smoke run's results.json matches the one recorded in golden/ (wall
times aside), compared as bayessim_exp/testing/golden.py says (exactly, but floats within a tolerance whose
measurement its docstring gives).

After a change that is meant to alter results, record the new reference and say why in the commit:
    python tests/integration/test_golden_results.py
Compare every recorded run by hand (prints "same" per run, or what differs):
    python tests/integration/test_golden_results.py --check
"""

import json
import sys
from pathlib import Path

import pytest

from bayessim_exp.testing.golden import RUNS, differences, run

pytestmark = pytest.mark.slow

GOLDEN = Path(__file__).parent / "golden"


def test_a_pendulum_smoke_run_matches_its_recorded_results(tmp_path):
    want = json.loads((GOLDEN / "pendulum_smoke.json").read_text())
    assert differences(run("pendulum_smoke", tmp_path), want) == []


def test_the_comparison_sees_a_changed_number():
    want = {"rounds": [{"log_prob_gain": 1.5, "held_out": {"gain": -0.05}, "proposal": "prior", "epochs": 5,
                        "guard": {"failed": True}, "posterior_mean": [0.9, 0.5]}]}

    def changed(**round_):
        return differences({"rounds": [{**want["rounds"][0], **round_}]}, want)

    # float32 noise, as measured: passes
    assert changed(log_prob_gain=1.5 * (1 + 7e-5), held_out={"gain": -0.05 + 8e-5}) == []
    # what a real change moves: caught
    assert changed(log_prob_gain=1.51) == ["results.rounds[0].log_prob_gain: 1.51 (recorded 1.5)"]
    assert changed(held_out={"gain": -0.0525}) == ["results.rounds[0].held_out.gain: -0.0525 (recorded -0.05)"]
    # anything but a float: exactly
    assert changed(proposal="truncated") == ["results.rounds[0].proposal: 'truncated' (recorded 'prior')"]
    assert changed(epochs=6) == ["results.rounds[0].epochs: 6 (recorded 5)"]
    assert changed(epochs=5.0) == ["results.rounds[0].epochs: 5.0 (recorded 5)"]
    assert changed(guard={"failed": False}) == ["results.rounds[0].guard.failed: False (recorded True)"]
    assert changed(posterior_mean=[0.9]) == ["results.rounds[0].posterior_mean: [0.9] (recorded [0.9, 0.5])"]
    assert changed(guard={"failed": True, "action": "fallback"}) == ["results.rounds[0].guard.action: only in one"]


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

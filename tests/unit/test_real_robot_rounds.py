"""benchmarks/real_robot_rounds.py's table: with --own, each round's own posterior at the truth beside what its guard
handed on."""

from __future__ import annotations

import json
import math

import torch

import real_robot_rounds  # benchmarks/real_robot_rounds.py (pyproject.toml's pytest pythonpath)
from bayessim_exp.data_files import save_state
from bayessim_exp.distributions.independent import GaussianPrior


def _round(k: int, action: str, gain: float) -> dict:
    return {"round": k, "proposal": "prior" if k == 1 else "truncated",
            "proposal_from": "the prior" if k == 1 else f"round {k - 1}'s posterior",
            "guard": {"action": action}, "log_prob_gain": gain, "log_prob_true_prior": -5.0}


def test_each_round_s_own_posterior_at_the_truth_whether_handed_on_or_not(tmp_path):
    """Round 1 fell back to the prior (gain 0) with its own posterior N(0, I) at the truth 0: gain log N(0; 0, I) + 5
    = +3.2 nats, the truth at HPD level 0; round 2 has no condition.pt (a run cut short): no own cell."""
    run = tmp_path / "run"
    (run / "round_001").mkdir(parents=True)
    save_state({"posterior": GaussianPrior(torch.zeros(2), torch.ones(2))}, run / "round_001" / "condition.pt")
    results = {"seed": 3, "param_names": ["a", "b"], "true_params": {"a": 0.0, "b": 0.0},
               "rounds": [_round(1, "fallback", 0.0), {**_round(2, "none", 1.5), "truth": {"hpd_level": 0.3}}]}
    (run / "results.json").write_text(json.dumps(results))
    gain = 5.0 - math.log(2 * math.pi)
    row = next(line for line in real_robot_rounds.rows(tmp_path, 0.01, own=True) if line.startswith("| 3"))
    assert f"prior -> fallback (+0.0; own {gain:+.1f} at 0.00); r1 post -> pass (+1.5) |" in row, row
    assert "; own" not in "".join(real_robot_rounds.rows(tmp_path, 0.01))
    assert "| +1.50 at 0.30 |" in row and "Truth inside the final 90 % region: 1 of 1 runs." in real_robot_rounds.rows(
        tmp_path, 0.01)

"""What every round of a sweep's runs proposed from, what its guard did and the gain at the truth: the table of
docs/benchmarks.md's "Rounds that escape and focus" (benchmarks/device/real_robot_studies.sh collects it).

    python benchmarks/real_robot_rounds.py multirun/nominal/<date> [more sweep dirs]

Per sweep: one row per job (seed), per round `proposal source -> guard action (gain)`, where the source is the
prior, a round's posterior, or what a round read off its real data (method.escape: its linear read, or the
simulations nearest them) and `pass` / `fallback`
is the guard's verdict, marked `[range]` where a real summary has more features outside the round's training
simulations' range than all but alpha / n of its held-out ones (the guard's range check since commit 9d7f36a,
applied where no replay widening is; the records of earlier commits keep what it reads); then the final gain at the
truth with the truth's HPD level in the final distribution (below 0.90: inside its 90 % region) and whether the run
meets issue 44's acceptance: some round passed the guard, and no round after the first
simulated from the prior. With --own each round's cell also has its own posterior's gain at the truth and the truth's
HPD level in it (from the run's round_NNN/condition.pt; also in probit space, where the model's spread is calibrated),
whether or not the guard handed it on: what a fallback gave up, or kept out.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np
import torch

from bayessim_exp.data_files import load_state
from bayessim_exp.diagnostics.mismatch import flag_outside
from bayessim_exp.diagnostics.scoring import truth_rank
from bayessim_exp.report.jobs import read_jobs

_SHORT = {"the prior": "prior", "linear read of its real data": "read", "simulations nearest its real data": "near",
          "posterior": "post"}


def _source(text: str) -> str:
    """'round 2's linear read of its real data' -> 'r2 read'."""
    if text == "the prior":
        return "prior"
    number, _, what = text.removeprefix("round ").partition("'s ")
    return f"r{number} {_SHORT.get(what, what)}"


def _range_mark(r: dict, alpha: float) -> str:
    outside = (r.get("mismatch") or {}).get("summaries_outside")
    return " [range]" if outside and flag_outside(outside, alpha)["flagged"] else ""


def _own(job, r: dict) -> str:
    """'; own +26.0 at 0.60, probit space 0.41': the round's own posterior's gain at the truth and the truth's HPD
    level in it, in parameter space and (a posterior defined there) in the model's probit space."""
    path = job.path / f"round_{r['round']:03d}" / "condition.pt"
    truth, prior_at_truth = job.results.get("true_params"), r.get("log_prob_true_prior")
    if not path.is_file() or truth is None or prior_at_truth is None:
        return ""
    posterior, names = load_state(path)["posterior"], job.results["param_names"]
    true = np.array([truth[name] for name in names])
    gain = float(posterior.log_prob(torch.as_tensor(true, dtype=torch.float64)[None])) - prior_at_truth
    rank = truth_rank(posterior, names, true, seed=0)
    level, probit = rank["hpd_level"], rank["hpd_level_probit"]
    return (f"; own {gain:+.1f} at {'n/a' if level is None else f'{level:.2f}'}"
            + ("" if probit is None else f", probit space {probit:.2f}"))


def rows(sweep: Path, alpha: float, own: bool = False) -> list[str]:
    jobs = [j for j in read_jobs(sweep) if j.results and j.results["rounds"]]
    out = [f"### {sweep.name} ({len(jobs)} runs with a round)", "",
           "| seed | rounds: proposal from -> guard (gain at the truth) | final gain at HPD level | a round passed | "
           "from the prior after round 1 |", "|---|---|---|---|---|"]
    finals, levels = [], []
    for job in jobs:
        rounds = job.results["rounds"]
        cells = []
        for r in rounds:
            verdict = "pass" if r["guard"]["action"] in ("none", "warn") else r["guard"]["action"]
            gain = r.get("log_prob_gain")
            cells.append(f"{_source(r.get('proposal_from', '?'))} -> {verdict}{_range_mark(r, alpha)} "
                         f"({'n/a' if gain is None else f'{gain:+.1f}'}{_own(job, r) if own else ''})")
        final, level = rounds[-1].get("log_prob_gain"), (rounds[-1].get("truth") or {}).get("hpd_level")
        finals.append(final)
        levels.append(level)
        passed = any(r["guard"]["action"] in ("none", "warn", "provisional") for r in rounds)
        from_prior = sum(r["proposal"] == "prior" for r in rounds[1:])
        status = "" if job.status == "finished" else f" ({job.status})"
        out.append(f"| {job.seed}{status} | {'; '.join(cells)} | "
                   f"{'n/a' if final is None else f'{final:+.2f}'} at {'n/a' if level is None else f'{level:.2f}'} | {'yes' if passed else 'no'} | {from_prior} |")
    known = [g for g in finals if g is not None]
    if known:
        out += ["", f"Final gain: median {statistics.median(known):+.2f}, min {min(known):+.2f} nats over {len(known)} runs."]
    if read := [v for v in levels if v is not None]:
        out += [f"Truth inside the final 90 % region: {sum(v < 0.9 for v in read)} of {len(read)} runs."]
    return out + [""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweeps", nargs="+", type=Path)
    parser.add_argument("--alpha", type=float, default=0.01, help="the range check's level (diagnostics.extrapolation_alpha)")
    parser.add_argument("--own", action="store_true", help="each round's own posterior at the truth, handed on or not")
    args = parser.parse_args()
    for sweep in args.sweeps:
        print("\n".join(rows(sweep, args.alpha, args.own)))


if __name__ == "__main__":
    main()

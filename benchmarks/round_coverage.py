"""Held-out coverage of every round's model on every task at its default budget, with the guard's verdicts.

    PYTHONPATH=src python benchmarks/round_coverage.py --jobs 3 --out /tmp/round_coverage device=cuda
    PYTHONPATH=src python benchmarks/round_coverage.py --tasks Pendulum Cartpole --jobs 2 debug=smoke   # a try
    PYTHONPATH=src python benchmarks/round_coverage.py --tasks Pendulum --also ShadowHand_more:1 -- sim=native

Runs `python -m bayessim_exp task=<task> seed=<seed> <overrides>` for every task and seed (whole runs in
parallel processes, `--jobs` at once), then prints per task, seed and round the expected coverage of the
50 % and 90 % HPD regions on that round's held-out simulations (diagnostics.held_out_fraction of its own,
drawn from its proposal), the band the guard accepts for that many pairs, the common factor its spread
calibration put on every standard deviation (models/spread.py) with the shares its validation pairs' 50 % and
90 % regions held before it, the held-out gain over the round's proposal, the coverage of 90 % regions near the
real data (diagnostics/local_coverage.py, with the override diagnostics.local_sets=100), the smallest p-value of
the real data's distance from the training simulations (diagnostics/extrapolation.py; the guard fails below
alpha / n), the guard's action, the mismatch flag, the log-density gain at the surrogate's truth and the
truth's HPD level (inside the 90 % region below 0.9), and the run's wall time. A run that fails is listed with
its last error line.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

# the longest runs first, so that parallel jobs end together
TASKS = ["ShadowHand_more", "ShadowHand", "Humanoid", "FrankaCabinet", "Anymal", "Ant", "BallBalance", "Quadcopter",
         "Ingenuity", "Cartpole", "Pendulum"]


def run(task: str, seed: int, overrides: list[str], out: Path) -> dict:
    run_dir = out / f"{task}_seed{seed}"
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "bayessim_exp", f"task={task}", f"seed={seed}", "logging.progress=false",
                           f"hydra.run.dir={run_dir}", *overrides], capture_output=True, text=True,
                          env={**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "4")})
    seconds = time.perf_counter() - t0
    results = run_dir / "results.json"
    if proc.returncode != 0 or not results.is_file():
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        return {"task": task, "seed": seed, "error": lines[-1] if lines else f"exit {proc.returncode}", "seconds": seconds}
    return {"task": task, "seed": seed, "results": json.loads(results.read_text()), "seconds": seconds}


def rows(outcome: dict) -> list[str]:
    from bayessim_exp.diagnostics.guard import coverage_band

    head = f"| {outcome['task']} | {outcome['seed']} "
    if "error" in outcome:
        return [head + f"| failed: {outcome['error'][:150]} | | | | | | | | | | | {outcome['seconds']:.0f} |"]
    out = []
    for r in outcome["results"]["rounds"]:
        cov, held = r.get("coverage") or {}, r.get("held_out") or {}
        hpd = cov.get("hpd", {})
        band = coverage_band(0.9, held.get("count", 0)) if held else (float("nan"),) * 2
        gain, truth = r.get("log_prob_gain"), (r.get("truth") or {}).get("hpd_level")
        local = ((r.get("local_coverage") or {}).get("hpd") or {}).get("0.9")
        outside = (r.get("extrapolation") or {}).get("min_p_value")
        joint = r.get("joint_spread")
        spread = "-" if joint is None else \
            f"{joint['factor']:.2f} ({joint['inside_unscaled']['0.5']:.2f} / {joint['inside_unscaled']['0.9']:.2f})"
        out.append(head + f"| {r['round']} | {hpd.get('0.5', float('nan')):.3f} | {hpd.get('0.9', float('nan')):.3f} | "
                   f"{band[0]:.3f}-{band[1]:.3f} | {spread} | "
                   f"{held.get('gain_over_proposal', float('nan')):+.2f} | "
                   f"{'-' if local is None else f'{local:.2f}'} | {'-' if outside is None else f'{outside:.3f}'} | "
                   f"{r['guard']['action']} | {'yes' if r['mismatch']['flagged'] else 'no'} | "
                   f"{'null' if gain is None else f'{gain:+.2f}'} | {'-' if truth is None else f'{truth:.2f}'} | "
                   f"{outcome['seconds']:.0f} |")
    return out


def _task_seed(run: str) -> tuple[str, int]:
    task, _, seed = run.partition(":")
    if task not in TASKS or not seed.isdigit():
        raise SystemExit(f"--also {run!r}: expected TASK:SEED with TASK one of {', '.join(TASKS)}")
    return task, int(seed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=TASKS, choices=TASKS)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--also", nargs="+", default=[], metavar="TASK:SEED", help="runs besides every task with every seed")
    ap.add_argument("--jobs", type=int, default=1, help="runs at once")
    ap.add_argument("--out", type=Path, default=Path("/tmp/round_coverage"))
    ap.add_argument("--json", type=Path, help="write every run's outcome here")
    ap.add_argument("overrides", nargs="*", help="added to every run (e.g. device=cuda)")
    args = ap.parse_args()
    jobs = [(task, seed) for task in args.tasks for seed in args.seeds] + [_task_seed(extra) for extra in args.also]
    jobs.sort(key=lambda job: TASKS.index(job[0]))  # the longest first, extra seeds with their task
    print("| task | seed | round | HPD 50 % | HPD 90 % | band (90 %) | spread factor (validation 50 % / 90 % at 1) "
          "| held-out gain over proposal "
          "| local 90 % | outside p | guard | mismatch | gain at truth | truth's HPD level | run s |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
          flush=True)
    outcomes = []
    with ThreadPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run, *job, args.overrides, args.out) for job in jobs]
        for future in as_completed(futures):  # each run's rows as soon as it ends
            outcome = future.result()
            outcomes.append(outcome)
            print("\n".join(rows(outcome)), flush=True)
            if args.json:  # after every run: what finished survives a run stopped at its time limit
                args.json.write_text(json.dumps(outcomes, indent=1))
    rounds = [r for o in outcomes if "results" in o for r in o["results"]["rounds"]]
    inside = sum(0.85 <= (r.get("coverage") or {}).get("hpd", {}).get("0.9", -1) <= 0.95 for r in rounds)
    print(f"\n{inside} of {len(rounds)} rounds with 90 % coverage in 0.85-0.95; "
          f"{sum(1 for o in outcomes if 'error' in o)} of {len(outcomes)} runs failed")


if __name__ == "__main__":
    main()

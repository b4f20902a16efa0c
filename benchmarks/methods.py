"""Compare inference methods from the results.json files of finished runs (e.g. one --multirun sweep).

    python -m bayessim_exp --config-dir sweeps --config-name methods --multirun   # Pendulum, Cartpole x 3 seeds
    python benchmarks/methods.py multirun/<date_time>

Per (task, method), over the seeds of finished runs, for the last round: the error of the mean to the true
parameters (mean over parameters of |mean - true| / prior range), the log density at the true
parameters and its gain over the prior, the real roll-outs used, simulated roll-outs, and the wall time
of the run (from its config.yaml, written at the start, to its results.json, rewritten after every round:
start-up and writing included, which the stage seconds in results.json leave out).
Prints mean ± sd over seeds, then each seed's value.
"""

from __future__ import annotations

import argparse
import statistics
from collections import defaultdict
from pathlib import Path

from bayessim_exp.report.jobs import read_job


def last_round(results: dict, run_dir: Path) -> dict:
    names, true, rnd = results["param_names"], results["true_params"], results["rounds"][-1]
    low, high = results["prior"]["low"], results["prior"]["high"]
    error = statistics.fmean(abs(rnd["posterior_mean"][n] - true[n]) / (high[n] - low[n]) for n in names)
    return {
        "mean error / range": error,
        "log p(true)": rnd["log_prob_true_posterior"],
        "gain over prior": rnd["log_prob_gain"],
        "real roll-outs": rnd["real_trajectories"],
        "sim roll-outs": sum(r["sim_trajectories"] for r in results["rounds"]),
        "wall s": (run_dir / "results.json").stat().st_mtime - (run_dir / "config.yaml").stat().st_mtime,
    }


def finished_runs(dirs: list[Path]) -> dict[tuple[str, str], list[tuple[Path, dict]]]:
    """(task, method) -> [(run dir, results.json)] of the runs under `dirs` with true parameters and every round."""
    runs: dict[tuple[str, str], list[tuple[Path, dict]]] = defaultdict(list)
    for d in dirs:
        for path in sorted(d.rglob("results.json")):
            job = read_job(path.parent)  # finished: every round it planned, the added ones included
            if job.status == "finished" and job.results.get("true_params"):
                runs[(job.results["task"], job.results["method"])].append((path.parent, job.results))
    return runs


def table(runs: dict[tuple[str, str], list[tuple[Path, dict]]]) -> str:
    """Markdown: per (task, method), mean ± sd over the seeds, then each seed's value."""
    rows = {key: [last_round(results, run_dir) for run_dir, results in found] for key, found in runs.items()}
    keys = list(next(iter(rows.values()))[0])
    lines = ["| task | method | seeds | " + " | ".join(keys) + " |", "|---|---|---|" + "---|" * len(keys)]
    for (task, method), found in sorted(rows.items()):
        cells = []
        for k in keys:
            values = [r[k] for r in found]
            spread = f" ± {statistics.stdev(values):.3g}" if len(values) > 1 else ""
            cells.append(f"{statistics.fmean(values):.3g}{spread} ({', '.join(f'{v:.3g}' for v in values)})")
        lines.append(f"| {task} | {method} | {len(found)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dirs", nargs="+", type=Path, help="run or sweep directories to search for results.json")
    args = parser.parse_args()
    runs = finished_runs(args.dirs)
    if not runs:
        raise SystemExit(f"no finished run with true parameters (results.json) under {args.dirs}")
    print(table(runs))


if __name__ == "__main__":
    main()

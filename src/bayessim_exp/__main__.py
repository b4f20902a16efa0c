"""`python -m bayessim_exp [overrides]`: compose the Hydra config and run the pipeline.

A single run that fails prints the error and exits 2. In --multirun every job runs: a failing job
writes `error.txt` into its run dir, and the sweep exits 1 at the end naming the failed jobs. The
task function returns the last round's log-density gain at the true parameters (NaN when unknown
or failed), so Hydra sweepers such as Optuna can optimise it.
"""

import atexit
import math
import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from . import job_failures
from .errors import ConfigError, DataError, PosteriorError, TrainingError
from .quick_exit import exit_without_finalization


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def _app(cfg: DictConfig) -> float:
    from .pipeline import run  # imports torch (seconds): --help answers without it

    hydra_cfg = HydraConfig.get()
    out_dir = hydra_cfg.runtime.output_dir
    if hydra_cfg.mode == RunMode.RUN:
        from .sim.mjx_impl import settle_for_one_run  # imports torch, as above

        settle_for_one_run(cfg.get("sim", {}))  # this process simulates this run's task only
    try:
        results = run(cfg, out_dir)
    except Exception as exc:  # noqa: BLE001 - every failure is reported; a sweep must go on
        expected = isinstance(exc, (ConfigError, DataError, PosteriorError, TrainingError))
        job_failures.record_failure(out_dir, exc, expected)
        if hydra_cfg.mode == RunMode.MULTIRUN:
            print(f"error in job {hydra_cfg.job.num} ({out_dir}): {exc}", file=sys.stderr)
            return math.nan
        if not expected:
            raise
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(summary_lines(results, out_dir)))
    gain = results["rounds"][-1]["log_prob_gain"]
    return math.nan if gain is None else float(gain)


def summary_lines(results: dict, out_dir) -> list[str]:
    """A finished run in a few lines: what it handed on (the last round's posterior, an earlier one or the prior),
    that distribution's means and standard deviations, and its gain at the truth where one is known."""
    last, rounds = results["rounds"][-1], len(results["rounds"])
    added = len(results.get("rounds_added", []))  # older runs lack the key
    lines = [f"{results['run_name']}: {rounds} rounds"
             + (f" ({added} added for an escape under way: method.escape_rounds)" if added else "") + f" -> {out_dir}"]
    handed_on = results.get("handed_on")
    if handed_on is not None:
        kept = "" if handed_on["round"] == rounds else (
            f", not round {rounds}'s posterior (the guard's warnings above; results.json: rounds[-1].guard)")
        lines.append(f"  handed on: {handed_on['name']}{kept}")
    for name in results["param_names"][:8]:
        lines.append(f"  {name:>20s}: {last['posterior_mean'][name]:.4g} +- {last['posterior_std'][name]:.3g}"
                     + (f"  (true {results['true_params'][name]:.4g})" if results["true_params"] else ""))
    if last["log_prob_gain"] is not None:
        lines.append(f"  log p(true | real) - log p(true) = {last['log_prob_gain']:.2f} nats")
    if len(results.get("integrators", [])) > 1:  # older runs lack the key
        lines.append(f"  simulated with the integrators {', '.join(results['integrators'])} alternating (method.integrators)")
    source = handed_on["round"] if handed_on else rounds  # the round whose posterior was handed on (0: the prior)
    if source > 0 and (error := results["rounds"][source - 1].get("summary_error")):  # older runs: no key
        features = error["features"]
        lines.append(f"  simulated summaries with noise in {len(features)} feature{'s' * (len(features) > 1)} the real "
                     f"data's replays left unexplained: {', '.join(map(str, features[:8]))}"
                     f"{', ...' if len(features) > 8 else ''} (method.summary_error)")
    return lines


def main() -> None:
    finished = []
    atexit.register(_exit_before_finalization, finished)  # the first registered: runs after every other handler
    _app()
    if job_failures.failed:
        print(f"{len(job_failures.failed)} job(s) failed (their error.txt says why):", file=sys.stderr)
        for job_dir in job_failures.failed:
            print(f"  {job_dir}", file=sys.stderr)
        sys.exit(1)
    finished.append(True)


def _exit_before_finalization(finished: list) -> None:
    """After a successful command only: every result is written and worker threads and processes are
    joined by the time the exit handlers run."""
    if finished:
        exit_without_finalization()


if __name__ == "__main__":
    main()

"""A failing job leaves its error in its run dir; a sweep goes on and names its failed jobs at the end.

The entry writes `error.txt` into the run dir of a job that raised; `FailedJobs`, a Hydra callback
run by the process that launched the sweep (whatever the launcher), collects them when the sweep
ends, and the entry then exits non-zero naming them. At that end it also writes the jobs' TensorBoard
hparams (report/hparams.py) and prints the commands that compare them: the report and TensorBoard.
"""

from __future__ import annotations

import logging
import traceback
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback

log = logging.getLogger(__name__)
ERROR_FILE = "error.txt"
failed: list[str] = []  # job dirs of the last sweep in this process that failed


def record_failure(run_dir: str | Path, exc: BaseException, expected: bool) -> None:
    """Write the error (with its traceback when it is a bug, not a user's mistake) beside the job's results."""
    text = f"{type(exc).__name__}: {exc}\n"
    if not expected:
        text += "\n" + "".join(traceback.format_exception(exc))
    path = Path(run_dir)
    path.mkdir(parents=True, exist_ok=True)
    (path / ERROR_FILE).write_text(text)


class FailedJobs(Callback):
    def on_multirun_start(self, config: Any, **kwargs: Any) -> None:
        failed.clear()

    def on_multirun_end(self, config: Any, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        failed.extend(sorted(str(p.parent) for p in sweep_dir.glob(f"*/{ERROR_FILE}")))
        if not sweep_dir.is_dir():
            return
        try:
            from .report.hparams import write_hparams

            write_hparams(sweep_dir)
        except Exception as exc:  # noqa: BLE001 - the jobs' results stand without their TensorBoard summary
            log.warning("TensorBoard hparams of %s not written: %s: %s", sweep_dir, type(exc).__name__, exc)
        print(f"sweep done: python -m bayessim_exp.report {sweep_dir}   (tables and plots; "
              f"tensorboard --logdir {sweep_dir} compares the jobs under HPARAMS)", flush=True)

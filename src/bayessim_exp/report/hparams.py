"""TensorBoard's HParams view of a sweep: `tensorboard --logdir <sweep dir>` then lists every finished job with its
configuration (components, seed, real.truth and the sweep's overrides) beside its final-round metrics (those of
summary.csv, under `hparams/`), to sort, filter and plot against each other.

One experiment summary (the hyperparameters and metrics every job is compared on) goes into the sweep dir, and each
finished job's session (its values and metrics) into its run dir beside the pipeline's own events, each in an
events file ending in `.hparams`, rewritten on every call: the sweep's end writes them (job_failures.py) and the
report's CLI refreshes them (after jobs were resumed or rerun).
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from .jobs import Job, configuration_labels, read_jobs
from .metrics import job_metrics

SUFFIX = ".hparams"
_COMPONENTS = ("task", "method", "model", "summarizer", "policy", "seed")


def job_hparams(job: Job, label: str) -> dict:
    """A job's hyperparameters: its components and seed from results.json, where its truth came from, then its
    overrides (the sweep's axes; the command line's spelling wins) and its configuration's label in the report."""
    results = job.results or {}
    out: dict = {k: results[k] for k in _COMPONENTS if results.get(k) is not None}
    out["real.truth"] = str(results.get("truth_source"))
    for item in job.overrides:
        key, _, text = item.lstrip("+~").partition("=")
        if key.startswith("hydra.") or key == "hydra/launcher":
            continue
        try:
            out[key] = yaml.safe_load(text)
        except yaml.YAMLError:
            out[key] = text
    out["configuration"] = label
    return out


def _typed(per_job: list[dict]) -> list[dict]:
    """Numbers stay numbers where every job has a number for the key; anything else becomes its text."""
    keys = {k for h in per_job for k in h}
    numeric = {k for k in keys if all(isinstance(h[k], (int, float)) and not isinstance(h[k], bool)
                                      for h in per_job if k in h)}
    return [{k: (v if k in numeric else str(v)) for k, v in h.items()} for h in per_job]


def _clear(directory: Path) -> None:
    for old in directory.glob(f"events.out.tfevents.*{SUFFIX}"):
        old.unlink()


def write_hparams(sweep_dir: str | Path) -> list[Path]:
    """Write the sweep's experiment summary and every finished job's session; returns the job dirs written."""
    from torch.utils.tensorboard import SummaryWriter
    from torch.utils.tensorboard.summary import hparams

    sweep_dir = Path(sweep_dir)
    jobs = [j for j in read_jobs(sweep_dir) if j.status == "finished"]
    if not jobs:
        return []
    labels = configuration_labels(jobs)
    per_job = _typed([job_hparams(j, labels[j.path]) for j in jobs])
    metrics = [{f"hparams/{k}": float(v) for k, v in job_metrics(j.results).items()
                if v is not None and math.isfinite(v)} for j in jobs]
    every_key: dict = {}
    for h in per_job:
        for k, v in h.items():
            every_key.setdefault(k, v)
    domains = {k: sorted({h[k] for h in per_job if k in h}) for k, v in every_key.items() if isinstance(v, str)}
    every_metric = {tag: 0.0 for m in metrics for tag in m}
    experiment, _, _ = hparams(every_key, every_metric, domains)

    _clear(sweep_dir)
    for job, values, measured in zip(jobs, per_job, metrics):
        _clear(job.path)
        _, start, end = hparams(values, measured, {k: d for k, d in domains.items() if k in values})
        with SummaryWriter(log_dir=str(job.path), filename_suffix=SUFFIX) as writer:
            if job.path == sweep_dir:  # a single run dir: the experiment is this one session
                writer.file_writer.add_summary(experiment)
            writer.file_writer.add_summary(start)
            writer.file_writer.add_summary(end)
            for tag, value in measured.items():
                writer.add_scalar(tag, value, len(job.results["rounds"]))
    if all(j.path != sweep_dir for j in jobs):
        with SummaryWriter(log_dir=str(sweep_dir), filename_suffix=SUFFIX) as writer:
            writer.file_writer.add_summary(experiment)
    return [j.path for j in jobs]

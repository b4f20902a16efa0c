"""Build a sweep's report: report.md, summary.csv (per configuration), jobs.csv (per job) and PNGs, and for a
known-truth study (truths that vary over its jobs) calibration.csv and, over truths drawn from the prior, sbc.csv
with the calibration section (calibration.py).

Failed and unfinished jobs are listed, never fatal: the tables use the finished jobs only, and a
figure that cannot be drawn is named in the report with the reason. Every mean says how many values it
is over, and the finished jobs that gave no value for a metric others measured are named: a null gain at
the truth means the posterior put zero density there, the worst outcome, never one to average away.
"""

from __future__ import annotations

import csv
import dataclasses
import logging
import math
from pathlib import Path

from . import calibration as calibration_section
from .figures import metric_figure, posterior_figure, rounds_figure
from .jobs import Job, configuration_labels, read_jobs
from .metrics import CONFIDENCE, Metric, interval, job_metrics, metrics_present

log = logging.getLogger(__name__)


@dataclasses.dataclass
class Report:
    out_dir: Path
    jobs: list[Job]
    figures: list[Path]
    figure_problems: list[str]

    def count(self, status: str) -> int:
        return sum(j.status == status for j in self.jobs)


def _fmt(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return ""
    return f"{value:.3g}"


def _cell(values: list[float | None], bounds) -> str:
    mean, lo, hi = interval(values, bounds)
    if math.isnan(mean):
        return "–"
    return _fmt(mean) if math.isnan(lo) else f"{_fmt(mean)} [{_fmt(lo)}, {_fmt(hi)}]"


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)


def build_report(sweep_dir: str | Path, out_dir: str | Path | None = None, posteriors: bool = True,
                 pool: bool = False) -> Report:
    sweep_dir = Path(sweep_dir)
    jobs = read_jobs(sweep_dir)
    if not jobs:
        raise FileNotFoundError(f"no job dirs under {sweep_dir} (looked for results.json, .hydra/ or error.txt)")
    out = Path(out_dir) if out_dir is not None else sweep_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    labels = configuration_labels(jobs, pool)
    finished = [j for j in jobs if j.status == "finished"]
    per_job = {j.path: job_metrics(j.results) for j in finished}
    metrics = metrics_present(list(per_job.values()))
    configs: dict[str, list[Job]] = {}
    for job in jobs:
        configs.setdefault(labels[job.path], [])
    for job in finished:
        configs[labels[job.path]].append(job)

    def values(metric: Metric, config: str) -> list[float | None]:
        return [per_job[j.path][metric.key] for j in configs[config]]

    def missing(metric: Metric, config: str) -> list[str]:
        return [j.path.name for j in configs[config] if not _finite(per_job[j.path][metric.key])]

    summary_rows = []
    for config, done in configs.items():
        all_jobs = [j for j in jobs if labels[j.path] == config]
        row = [config, len(done), sum(j.status == "failed" for j in all_jobs), sum(j.status == "unfinished" for j in all_jobs)]
        for metric in metrics:
            row += [_fmt(v) for v in interval(values(metric, config), metric.bounds)]
            row.append(len(done) - len(missing(metric, config)))
        row.append("; ".join(f"{m.key}: {' '.join(missing(m, config))}" for m in metrics if missing(m, config)))
        summary_rows.append(row)
    _write_csv(out / "summary.csv", ["configuration", "finished", "failed", "unfinished"]
               + [f"{m.key}_{part}" for m in metrics for part in ("mean", "ci_low", "ci_high", "n")]
               + ["missing values"], summary_rows)
    studies = {c: calibration_section.calibration(d) for c, d in configs.items()}
    studies = {c: study for c, study in studies.items() if study is not None}
    fixed = {c: calibration_section.fixed_truth(d) for c, d in configs.items() if c not in studies}
    fixed = {c: why for c, why in fixed.items() if why is not None}
    if studies:
        _write_csv(out / "calibration.csv", calibration_section.CSV_HEADER,
                   [calibration_section.csv_row(c, study) for c, study in studies.items()])
        sbc_rows = [row for c, study in studies.items() for row in calibration_section.sbc_rows(c, study)]
        if sbc_rows:
            _write_csv(out / "sbc.csv", calibration_section.SBC_CSV_HEADER, sbc_rows)
    _write_csv(out / "jobs.csv", ["job", "configuration", "seed", "status", "problem"] + [m.key for m in metrics],
               [[j.path.relative_to(sweep_dir).as_posix() or ".", labels[j.path], j.seed, j.status, j.problem]
                + [_fmt(per_job.get(j.path, {}).get(m.key)) for m in metrics] for j in jobs])

    figures, problems = [], []
    with_data = {c: d for c, d in configs.items() if d}
    for metric in metrics:
        figures.append(metric_figure(metric, {c: values(metric, c) for c in with_data}, out / f"{metric.key}.png"))
    if with_data:
        figures.append(rounds_figure(with_data, out / "gain_by_round.png"))
    rank_figures = {}
    for k, (config, study) in enumerate(studies.items()):
        rank_figures[config] = calibration_section.rank_figure(study, config, out / f"sbc_ranks_{k:02d}.png")
    if posteriors:
        for k, (config, done) in enumerate(with_data.items()):
            target = out / f"posterior_{k:02d}.png"
            try:
                figures.append(posterior_figure(done[0], config, target))
            except Exception as exc:  # a report lists what it could not draw and goes on
                log.warning("posterior of %s: %s", done[0].path, exc)
                problems.append(f"posterior of `{config}` ({done[0].path.name}): {type(exc).__name__}: {exc}")
    report = Report(out, jobs, figures, problems)
    lines = _markdown(sweep_dir, report, configs, metrics, values, missing)
    if fixed:
        lines += ["", "## Known truths", ""] + [f"- `{c}`: {why}" for c, why in fixed.items()]
    if studies:
        lines += ["", "## Calibration (known truths)", "",
                  "Where each job's truth lies in its final posterior (sweeps/calibration.yaml draws the truths from "
                  "the prior, sweeps/nominal.yaml puts them at the MJCF's values with a few moved): a calibrated "
                  "pipeline holds about L of them in its level-L regions, and over truths drawn from the prior its SBC "
                  "rank histograms are flat within the grey band (KS p-values and C2ST accuracies below each).", ""]
        for config, study in studies.items():
            lines += calibration_section.markdown(config, study, rank_figures[config])
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return report


def _finite(value: float | None) -> bool:
    return value is not None and math.isfinite(value)


def _markdown(sweep_dir: Path, report: Report, configs: dict[str, list[Job]], metrics: list[Metric], values,
              missing) -> list[str]:
    lines = [f"# Sweep report: {sweep_dir}", "",
             f"{len(report.jobs)} jobs: {report.count('finished')} finished, {report.count('failed')} failed, "
             f"{report.count('unfinished')} unfinished. Each cell: the mean over the finished seeds of the final "
             f"round, with the Student-t {CONFIDENCE:.0%} confidence interval of that mean in brackets (none with "
             "one value), and (n = k) where it is over fewer values than seeds (below: which jobs gave none). "
             "Metrics: " + "; ".join(f"`{m.key}` = {m.label}" for m in metrics) + ".", ""]
    header = ["configuration", "seeds"] + [f"`{m.key}`" for m in metrics]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for config, done in configs.items():
        cells = []
        for m in metrics:
            short = len(missing(m, config))
            cells.append(_cell(values(m, config), m.bounds) + (f" (n = {len(done) - short})" if short and done else ""))
        lines.append("| " + " | ".join([config, str(len(done))] + cells) + " |")
    gaps = [(config, m, missing(m, config)) for config in configs for m in metrics if missing(m, config)]
    lines += ["", "## Missing values", ""]
    for config, m, names in gaps:
        what = ("**the final posterior put zero density at the truth** (the worst outcome: not in the mean)"
                if m.key == "log_prob_gain" else "no value (not measured, or not finite)")
        lines.append(f"- `{config}`, `{m.key}`: {', '.join(f'`{n}`' for n in names)}: {what}")
    if not gaps:
        lines.append("none: every mean is over every finished seed")
    bad = [j for j in report.jobs if j.status != "finished"]
    lines += ["", "## Failed or unfinished jobs", ""]
    lines += [f"- `{j.path.relative_to(sweep_dir).as_posix() or '.'}`: {j.status}: {j.problem}" for j in bad] or ["none"]
    lines += ["", "## Figures", ""]
    lines += [f"![{p.stem}]({p.name})" for p in report.figures]
    if report.figure_problems:
        lines += ["", "Not drawn:", ""] + [f"- {p}" for p in report.figure_problems]
    return lines

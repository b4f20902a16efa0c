"""The report's PNGs: one per metric (configurations side by side, every seed a dot, the mean with
its 95 % interval), the gain over rounds, and one zoomed posterior pair plot per configuration."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .jobs import Job  # noqa: E402
from .metrics import Metric, gain_by_round, interval  # noqa: E402


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def metric_figure(metric: Metric, values: dict[str, list[float]], path: Path) -> Path:
    """values: configuration -> one value per finished seed."""
    labels = list(values)
    fig, ax = plt.subplots(figsize=(max(4.0, 1.1 * len(labels) + 2), 3.8))
    rng = np.random.default_rng(0)  # jitter only, so that seeds with equal values stay visible
    for k, label in enumerate(labels):
        seeds = np.array([v for v in values[label] if v is not None and np.isfinite(v)], dtype=float)
        if len(seeds) == 0:
            continue
        ax.plot(k + rng.uniform(-0.12, 0.12, len(seeds)), seeds, "o", color="C0", alpha=0.6, ms=5,
                label="seeds" if k == 0 else None)
        mean, lo, hi = interval(list(seeds), metric.bounds)
        err = None if np.isnan(lo) else [[mean - lo], [hi - mean]]
        ax.errorbar(k + 0.3, mean, yerr=err, fmt="s", color="black", capsize=4, ms=5,
                    label="mean, 95 % interval" if k == 0 else None)
    if metric.reference is not None:
        ax.axhline(metric.reference, color="0.5", ls="--", lw=1)
    ax.set_xticks(range(len(labels)), labels, rotation=20 if len(labels) > 3 else 0, ha="right" if len(labels) > 3 else "center",
                  fontsize=8)
    ax.set_xlim(-0.6, len(labels) - 0.3)
    ax.set_ylabel(metric.label, fontsize=9)
    ax.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    return _save(fig, path)


def rounds_figure(jobs_by_config: dict[str, list[Job]], path: Path) -> Path:
    """Log-density gain at the true parameters after each round: the mean over seeds with the seeds' range."""
    fig, ax = plt.subplots(figsize=(6, 3.8))
    for k, (label, jobs) in enumerate(jobs_by_config.items()):
        series = [gain_by_round(j.results) for j in jobs]
        n = max(len(s) for s in series)
        grid = np.full((len(series), n), np.nan)
        for i, s in enumerate(series):
            grid[i, : len(s)] = [np.nan if v is None else v for v in s]
        if np.isnan(grid).all():
            continue
        rounds = np.arange(1, n + 1)
        with np.errstate(all="ignore"):
            ax.plot(rounds, np.nanmean(grid, 0), "o-", color=f"C{k}", label=label)
            ax.fill_between(rounds, np.nanmin(grid, 0), np.nanmax(grid, 0), color=f"C{k}", alpha=0.2)
    ax.axhline(0.0, color="0.5", ls="--", lw=1)
    ax.set_xlabel("round")
    ax.set_ylabel("log-density gain at the true parameters (nats)", fontsize=9)
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.legend(fontsize=8, frameon=False, title="mean over seeds; band: min to max", title_fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def posterior_figure(job: Job, label: str, path: Path, num_samples: int = 5000) -> Path:
    """The final round's posterior of one job, drawn as the run's TensorBoard pair plot."""
    # torch and the run's components (seconds): only a report with posterior figures pays for them
    import torch

    from .. import api, registry
    from ..logging.plots import pair_plot

    run = api.load_run(job.path)
    results, cfg = run.results, run.config
    names = results["param_names"]
    plot_names = list(cfg.logging.plot_params) if cfg.logging.plot_params is not None \
        else names[: cfg.logging.max_plot_params]
    idx = [names.index(n) for n in plot_names]
    registry.load_plugins(list(cfg.plugins))
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    with torch.random.fork_rng():
        torch.manual_seed(0)
        samples = run.posterior().sample((num_samples,)).double().numpy()[:, idx]
        prior_samples = prior.sample((num_samples,)).double().numpy()[:, idx]
    low = np.array([results["prior"]["low"][n] for n in plot_names])
    high = np.array([results["prior"]["high"][n] for n in plot_names])
    true = None if results["true_params"] is None else np.array([results["true_params"][n] for n in plot_names])
    fig = pair_plot(samples, plot_names, low, high, true,
                    f"{label}, seed {results['seed']}: posterior after round {len(results['rounds'])}", prior_samples)
    return _save(fig, path)

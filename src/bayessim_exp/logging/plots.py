"""Pair plots of posterior samples: 1D marginals with the prior and true value, 2D with the true value."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def pair_plot(samples: np.ndarray, names: list[str], low: np.ndarray, high: np.ndarray,
              true: np.ndarray | None, title: str, prior_samples: np.ndarray | None = None) -> plt.Figure:
    """samples [n, d] of the posterior; prior_samples [m, d] drawn from the prior for its marginals."""
    d = len(names)
    fig, axes = plt.subplots(d, d, figsize=(2.4 * d + 1, 2.4 * d + 1), squeeze=False)
    for i in range(d):
        for j in range(d):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                bins = np.linspace(low[i], high[i], 41)
                if prior_samples is not None:
                    ax.hist(prior_samples[:, i], bins=bins, density=True, color="0.75", label="prior")
                ax.hist(samples[:, i], bins=bins, density=True, histtype="step", color="C0", lw=1.5, label="posterior")
                if true is not None:
                    ax.axvline(true[i], color="red", lw=1, label="true")
                ax.set_xlim(low[i], high[i])
                ax.set_yticks([])
            else:
                ax.hist2d(samples[:, j], samples[:, i], bins=40, range=[[low[j], high[j]], [low[i], high[i]]], cmap="Blues")
                if true is not None:
                    ax.plot(true[j], true[i], marker="x", color="red", ms=8, mew=2)
            if i == d - 1:
                ax.set_xlabel(names[j])
            if j == 0 and i > 0:
                ax.set_ylabel(names[i])
    axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def replay_plot(real: np.ndarray, posterior: np.ndarray, prior: np.ndarray, obs_names: list[str], dt: float,
                p_values: list[float], title: str, max_lines: int = 20) -> plt.Figure:
    """Real trajectories [n, T+1, S] (black) over replays at posterior [n, m, T+1, S] (blue) and prior (grey)
    draws from the same initial states under the same actions; one row per trajectory, one column per feature."""
    n, s = real.shape[0], real.shape[-1]
    fig, axes = plt.subplots(n, s, figsize=(3 * s + 1, 2.2 * n + 1), squeeze=False)
    t = dt * np.arange(real.shape[1])
    for i in range(n):
        for j in range(s):
            ax = axes[i, j]
            ax.plot(t, prior[i, :max_lines, :, j].T, color="0.75", lw=0.6)
            ax.plot(t, posterior[i, :max_lines, :, j].T, color="C0", lw=0.6, alpha=0.7)
            ax.plot(t, real[i, :, j], color="black", lw=1.5)
            if i == 0:
                ax.set_title(obs_names[j], fontsize=9)
            if j == 0:
                ax.set_ylabel(f"real {i}\np = {p_values[i]:.3g}", fontsize=8)
            if i == n - 1:
                ax.set_xlabel("time [s]")
    fig.suptitle(f"{title}: real (black), posterior replays (blue), prior replays (grey)")
    fig.tight_layout()
    return fig

"""Pair plots of posterior samples, zoomed to where the posterior is.

A narrow posterior drawn on the prior's axes is one histogram bin and a dot, so every panel is
zoomed to the posterior's range; a strip above each marginal shows that window inside the prior's
range. Diagonal: the posterior's marginal density over the prior's. Below it: 2-D density contours
of the 50 % and 90 % highest-density regions. The true value is a red line or cross, or an arrow at
the edge when it lies outside the window.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from scipy.ndimage import gaussian_filter  # noqa: E402

MASS_LEVELS = (0.9, 0.5)  # highest-density regions drawn in the 2-D panels, widest first
_WINDOW_QUANTILES = (0.005, 0.995)  # the window holds 99 % of the posterior's marginal, padded
_PAD = 0.15
_MIN_WIDTH = 1e-3  # of the prior's width: a posterior collapsed to a point still gets a readable window
_GRID = 50  # cells per axis of the 2-D density
_SMOOTHING = 1.5  # cells: Gaussian smoothing of the 2-D histogram before contouring
_CHAR_WIDTH = 0.55 / 72  # inches per character per point of font size (a generous average for the default font)


def _margins(fig: plt.Figure, left: float, right: float, bottom: float, top: float, between_x: float = 0.0,
             between_y: float = 0.0) -> None:
    """Margins and gaps between panels in inches, laid out once: matplotlib's tight_layout measures every tick
    label by drawing the figure an extra time (its cost: docs/benchmarks.md)."""
    width, height = fig.get_size_inches()
    grid = fig.axes[0].get_subplotspec().get_gridspec()
    rows, cols = grid.get_geometry()
    panel_w = (width - left - right - (cols - 1) * between_x) / cols
    panel_h = (height - bottom - top - (rows - 1) * between_y) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height,
                        wspace=between_x / panel_w, hspace=between_y / panel_h)


def zoom_window(values: np.ndarray, low: float, high: float, true: float | None = None) -> tuple[float, float]:
    """The x-range of one parameter's panels: the posterior's central 99 %, padded, inside [low, high];
    widened to take in the true value when that is at most one window width away."""
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return float(low), float(high)
    q_lo, q_hi = np.quantile(values, _WINDOW_QUANTILES)
    lo, hi = q_lo - _PAD * (q_hi - q_lo), q_hi + _PAD * (q_hi - q_lo)
    if true is not None and np.isfinite(true) and lo - (hi - lo) <= true <= hi + (hi - lo):
        margin = _PAD * (hi - lo)
        lo, hi = min(lo, true - margin), max(hi, true + margin)
    min_width = _MIN_WIDTH * (high - low)
    if hi - lo < min_width:
        centre = 0.5 * (lo + hi)
        lo, hi = centre - 0.5 * min_width, centre + 0.5 * min_width
    return float(max(lo, low)), float(min(hi, high))


def hpd_thresholds(density: np.ndarray, masses=MASS_LEVELS) -> list[float]:
    """Density values whose super-level sets hold `masses` of the total (cells sorted high to low)."""
    flat = np.sort(density.ravel())[::-1]
    cumulative = np.cumsum(flat) / flat.sum()
    return [float(flat[min(np.searchsorted(cumulative, m), len(flat) - 1)]) for m in masses]


def _marginal(ax, i, samples, prior_samples, window, true, flat_density):
    """`flat_density`: the density of a flat distribution, drawn as it is rather than as its draws' histogram."""
    bins = np.linspace(*window, 41)
    width = bins[1] - bins[0]
    if prior_samples is not None:
        counts, _ = np.histogram(prior_samples[:, i], bins)
        ax.stairs(counts / (len(prior_samples) * width), bins, fill=True, color="0.85", label="prior")
    if flat_density is None:
        counts, _ = np.histogram(samples[:, i], bins)
        ax.stairs(counts / (len(samples) * width), bins, color="C0", lw=1.5, label="posterior")
    else:
        ax.stairs([flat_density], window, color="C0", lw=1.5, label="posterior")
    _mark_true_1d(ax, true, window)
    ax.set_xlim(*window)
    ax.set_yticks([])


def _mark_true_1d(ax, true, window):
    if true is None:
        return
    if window[0] <= true <= window[1]:
        ax.axvline(true, color="red", lw=1.2, label="true")
    else:
        right = true > window[1]
        ax.annotate(f"true {true:.3g} " + ("\u2192" if right else "\u2190"), xy=(0.98 if right else 0.02, 0.9),
                    xycoords="axes fraction", ha="right" if right else "left", color="red", fontsize=7)


def _prior_strip(ax, low, high, window, true):
    """A thin bar above a marginal: the prior's range, the zoomed window on it, the true value."""
    strip = ax.inset_axes([0.0, 1.04, 1.0, 0.1])
    strip.plot([low, high], [0, 0], color="0.6", lw=3, solid_capstyle="butt")
    strip.plot(window, [0, 0], color="C0", lw=6, solid_capstyle="butt")
    if true is not None:
        strip.plot([true], [0], marker="|", color="red", ms=9, mew=2)
    strip.set_xlim(low - 0.02 * (high - low), high + 0.02 * (high - low))
    strip.set_ylim(-1, 1)
    strip.axis("off")
    strip.text(0.0, 1.2, f"{low:.3g}", transform=strip.transAxes, fontsize=6, ha="left", va="bottom", color="0.4")
    strip.text(1.0, 1.2, f"{high:.3g}", transform=strip.transAxes, fontsize=6, ha="right", va="bottom", color="0.4")


def _joint(ax, x, y, window_x, window_y, true_xy, flat):
    if flat:  # no region of a flat density holds more than its area's share: contours would trace the draws' noise
        ax.axvspan(*window_x, color="#9ecae1")
        ax.text(0.5, 0.5, "flat", transform=ax.transAxes, ha="center", va="center", fontsize=8, color="#08519c")
    else:
        _regions(ax, x, y, window_x, window_y)
    if true_xy is not None and window_x[0] <= true_xy[0] <= window_x[1] and window_y[0] <= true_xy[1] <= window_y[1]:
        ax.plot(*true_xy, marker="x", color="red", ms=8, mew=2)
    ax.set_xlim(*window_x)
    ax.set_ylim(*window_y)


def _regions(ax, x, y, window_x, window_y):
    """The 50 % and 90 % highest-density regions of the draws (x, y), from their smoothed 2-D histogram."""
    counts, xe, ye = np.histogram2d(x, y, bins=_GRID, range=[window_x, window_y])
    density = gaussian_filter(counts, _SMOOTHING)
    levels = sorted(set(hpd_thresholds(density)) | {float(density.max())}) if density.sum() > 0 else []
    if len(levels) >= 2 and levels[0] > 0:
        centres_x, centres_y = 0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1])
        ax.contourf(centres_x, centres_y, density.T, levels=levels, colors=["#9ecae1", "#3182bd"][-len(levels) + 1:])
        ax.contour(centres_x, centres_y, density.T, levels=levels[:-1], colors="#08519c", linewidths=0.8)
    else:  # too few distinct cells for contours (a point mass): show the draws themselves
        ax.plot(x[:500], y[:500], ".", color="C0", ms=2)


def pair_plot(samples: np.ndarray, names: list[str], low: np.ndarray, high: np.ndarray,
              true: np.ndarray | None, title: str, prior_samples: np.ndarray | None = None,
              flat: bool = False) -> plt.Figure:
    """samples [n, d] of the posterior; prior_samples [m, d] drawn from the prior for its marginals; `flat`: the
    samples' distribution is uniform on [low, high] (a uniform prior handed on), drawn as such."""
    samples = samples[np.isfinite(samples).all(1)]
    d = len(names)
    windows = [zoom_window(samples[:, i], low[i], high[i], None if true is None else true[i]) for i in range(d)]
    size = max(2.6 * d + 1.2, 5.0)
    fig, axes = plt.subplots(d, d, figsize=(size, size), squeeze=False)
    for i in range(d):
        t_i = None if true is None else float(true[i])
        for j in range(d):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
            elif i == j:
                _marginal(ax, i, samples, prior_samples, windows[i], t_i,
                          1 / (high[i] - low[i]) if flat else None)
                _prior_strip(ax, float(low[i]), float(high[i]), windows[i], t_i)
            else:
                _joint(ax, samples[:, j], samples[:, i], windows[j], windows[i],
                       None if true is None else (float(true[j]), float(true[i])), flat)
            if i == d - 1:
                ax.set_xlabel(names[j])
            if j == 0 and i > 0:
                ax.set_ylabel(names[i])
            ax.tick_params(labelsize=7)
    if d == 1:
        axes[0, 0].legend(fontsize=7, loc="upper left", frameon=False)
    else:  # in the empty upper triangle
        from matplotlib.patches import Patch

        handles, labels = axes[0, 0].get_legend_handles_labels()
        handles += [Patch(color="#3182bd"), Patch(color="#9ecae1")]
        labels += ["50 % region", "90 % region"]
        fig.legend(handles, labels, loc="upper right", bbox_to_anchor=(0.99, 0.93), fontsize=8, frameon=False)
    fig.suptitle(f"{title}\nzoomed to the posterior; bars: the window in the prior's range",
                 fontsize=9)
    # room for 7-point tick labels beside and below every panel, the prior's strip above the diagonal's (its
    # height a share of the panel's: a lone panel is the tallest)
    _margins(fig, left=0.75, right=0.2, bottom=0.55, top=1.05 if d > 1 else 1.3, between_x=0.45, between_y=0.6)
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
            # one collection per colour rather than a Line2D per replay: a fraction of the drawing time
            ax.add_collection(_lines(t, prior[i, :max_lines, :, j], color="0.75", lw=0.6))
            ax.add_collection(_lines(t, posterior[i, :max_lines, :, j], color="C0", lw=0.6, alpha=0.7))
            ax.plot(t, real[i, :, j], color="black", lw=1.5)
            if i == 0:
                ax.set_title(obs_names[j], fontsize=9)
            if j == 0:
                ax.set_ylabel(f"real {i}\np = {p_values[i]:.3g}", fontsize=8)
            if i == n - 1:
                ax.set_xlabel("time [s]")
    fig.suptitle(f"{title}: real (black), posterior replays (blue), prior replays (grey)")
    _margins(fig, left=1.05, right=0.15, bottom=0.55, top=0.65, between_x=0.6, between_y=0.35)
    return fig


def identifiability_plot(names: list[str], r2: list[float], rms: list[float] | None, title: str) -> plt.Figure:
    """Per parameter: the held-out R^2 of the summaries' linear read and, in round 1, the local sensitivity at the
    nominal parameters (red: below NO_EFFECT, the parameter moves nothing)."""
    from ..diagnostics.identifiability import NO_EFFECT  # imports torch: only where this figure is drawn

    views = 1 if rms is None else 2
    fig, axes = plt.subplots(1, views, figsize=(4.5 * views + 1.5, 0.22 * len(names) + 1.6), squeeze=False, sharey=True)
    ticks = np.arange(len(names))
    axes[0, 0].barh(ticks, np.clip(r2, -0.1, 1.0), color="C0")  # an overfit read below 0 says as little as 0
    axes[0, 0].set_xlim(-0.1, 1.0)
    axes[0, 0].set_xlabel("held-out R$^2$ of a linear read of the summaries\n(a lower bound on the expected contraction)")
    axes[0, 0].set_yticks(ticks, names, fontsize=7)
    axes[0, 0].invert_yaxis()
    if rms is not None:
        ax = axes[0, 1]
        ax.barh(ticks, np.maximum(rms, 1e-6), color=["C3" if v < NO_EFFECT else "C0" for v in rms])
        ax.axvline(NO_EFFECT, color="0.4", ls="--", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("summaries moved per prior std at the nominal\n(RMS, standardised; red: no effect)")
    fig.suptitle(f"identifiability, {title}", fontsize=9)
    _margins(fig, left=0.25 + 7 * _CHAR_WIDTH * max(map(len, names)), right=0.2, bottom=0.75, top=0.35,
             between_x=0.25)
    return fig


def _lines(t: np.ndarray, ys: np.ndarray, **style) -> LineCollection:
    """The rows of ys [k, T] over t [T] as one artist."""
    return LineCollection(np.stack([np.broadcast_to(t, ys.shape), ys], -1), **style)

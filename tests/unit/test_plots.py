"""The posterior pair plot zooms to the posterior, draws density contours, and keeps the true value in sight."""

import numpy as np
import pytest
from matplotlib.contour import QuadContourSet

from bayessim_exp.logging.plots import hpd_thresholds, pair_plot, replay_plot, zoom_window


def test_zoom_window_follows_the_posterior_not_the_prior():
    narrow = np.random.default_rng(0).normal(1.0, 0.01, 5000)
    lo, hi = zoom_window(narrow, 0.5, 2.0)
    assert 0.95 < lo < 0.98 and 1.02 < hi < 1.05
    lo_t, hi_t = zoom_window(narrow, 0.5, 2.0, true=1.06)  # a little outside: taken in
    assert lo_t == lo and 1.06 < hi_t < 1.07
    assert zoom_window(narrow, 0.5, 2.0, true=1.9) == (lo, hi)  # far away: left to an arrow
    assert zoom_window(np.random.default_rng(0).uniform(0.5, 2.0, 5000), 0.5, 2.0) == (0.5, 2.0)  # clipped to the prior
    lo_p, hi_p = zoom_window(np.full(100, 1.0), 0.5, 2.0)  # a point mass still gets a window
    assert hi_p - lo_p == pytest.approx(1.5e-3) and lo_p < 1.0 < hi_p


def test_hpd_thresholds_enclose_the_asked_mass():
    density = np.random.default_rng(1).gamma(0.5, size=(40, 40))
    for mass, threshold in zip((0.9, 0.5), hpd_thresholds(density, (0.9, 0.5))):
        inside = density[density >= threshold].sum() / density.sum()
        assert mass <= inside < mass + density.max() / density.sum()


def test_pair_plot_panels_are_zoomed_with_contours_and_the_true_value():
    rng = np.random.default_rng(2)
    low, high = np.array([0.5, 0.1]), np.array([2.0, 1.0])
    samples = rng.multivariate_normal([1.0, 0.5], [[1e-4, 5e-5], [5e-5, 1e-4]], 5000)
    fig = pair_plot(samples, ["mass", "damping"], low, high, np.array([1.01, 0.9]), "round 3",
                    rng.uniform(low, high, (5000, 2)))
    axes = np.array(fig.axes[:4]).reshape(2, 2)
    width = np.diff(axes[0, 0].get_xlim())[0]
    assert width < 0.1 * (high[0] - low[0])  # not the prior's axis any more
    assert axes[0, 0].get_xlim()[0] <= 1.01 <= axes[0, 0].get_xlim()[1]
    assert any(isinstance(c, QuadContourSet) for c in axes[1, 0].get_children())
    assert any("true 0.9" in t.get_text() for t in axes[1, 1].texts)  # outside the damping window: an arrow


def test_replay_plot_draws_each_colour_as_one_collection_within_the_axes():
    rng = np.random.default_rng(3)
    real, posterior, prior = rng.normal(size=(2, 11, 3)), rng.normal(size=(2, 30, 11, 3)), 5 + rng.normal(size=(2, 30, 11, 3))
    posterior[0, 1, 5:, 0] = np.nan  # a replay that diverged
    fig = replay_plot(real, posterior, prior, ["a", "b", "c"], 0.1, [0.5, 0.01], "round 1", max_lines=20)
    assert len(fig.axes) == 6
    for ax in fig.axes:
        assert [len(c.get_segments()) for c in ax.collections] == [20, 20]
        assert len(ax.lines) == 1  # the real trajectory
        low, high = ax.get_ylim()
        assert low < -1 and high > 6  # the prior's replays around 5 are in view

"""real.truth=prior: each seed's surrogate parameters drawn from the prior (the known-truth calibration study)."""

import numpy as np
import pytest

from bayessim_exp.errors import ConfigError
from bayessim_exp.pipeline import Pipeline


def _truth(compose, tmp_path, *overrides):
    return Pipeline(compose(["debug=smoke", *overrides]), tmp_path).real_source.true_params


def test_each_seed_draws_its_own_truth_from_the_prior_reproducibly(compose, tmp_path):
    truths = [_truth(compose, tmp_path / str(seed), "real.truth=prior", f"seed={seed}") for seed in range(20)]
    low, high = np.array([0.5, 0.25]), np.array([2.0, 1.0])  # conf/task/Pendulum.yaml
    assert all(((t >= low) & (t <= high)).all() for t in truths)
    assert len({tuple(t) for t in truths}) == 20
    spread = np.std(truths, axis=0) / (high - low)
    assert (spread > 0.2).all()  # a uniform draw's std is 0.29 of its range
    np.testing.assert_array_equal(_truth(compose, tmp_path / "again", "real.truth=prior", "seed=3"), truths[3])


def test_the_default_truth_is_the_tasks_and_an_unknown_one_is_refused(compose, tmp_path):
    np.testing.assert_array_equal(_truth(compose, tmp_path / "task"), [1.0, 0.5])
    with pytest.raises(ConfigError, match="truth='sampled' not allowed; allowed: task, prior"):
        _truth(compose, tmp_path / "bad", "real.truth=sampled")

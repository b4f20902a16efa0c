"""real.truth=prior: each seed's surrogate parameters drawn from the prior (the known-truth calibration study)."""

import numpy as np
import pytest

from bayessim_exp.errors import ConfigError
from bayessim_exp.pipeline import Pipeline


def _truth(compose, tmp_path, *overrides):
    return Pipeline(compose(["debug=smoke", *overrides]), tmp_path).real_source.true_params


@pytest.mark.slow  # 21 pipelines built: make test, not make test-fast
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


def test_nominal_truths_are_the_mjcf_values_then_one_to_three_moved(compose, tmp_path):
    """real.truth=nominal: seed 0 every parameter at its nominal value (kept 2 % inside the prior's CDF: Pendulum's
    length of 1 m is the box's face), later seeds 1 + (seed - 1) % 3 parameters with a nonzero nominal moved x0.5 or
    x2, then kept inside; Cartpole's additive parameters (nominal 0) at 2 % of their ranges, never moved."""
    np.testing.assert_allclose(_truth(compose, tmp_path / "p0", "real.truth=nominal", "seed=0"), [1.0, 0.985])
    nominal = _truth(compose, tmp_path / "c0", "task=Cartpole", "real.truth=nominal", "seed=0")
    additive = slice(4, 12)  # conf/task/Cartpole.yaml: dampings, stiffnesses, frictions, armatures
    np.testing.assert_allclose(nominal[[0, 1, 2, 3, 12]], [1.0, 0.1, 1.0, 0.05, 10.0])
    low = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    high = np.array([5.0, 0.05, 10.0, 0.5, 1.0, 0.02, 1.0, 0.02])
    np.testing.assert_allclose(nominal[additive], low + 0.02 * (high - low))
    for seed in range(1, 7):
        moved = _truth(compose, tmp_path / f"c{seed}", "task=Cartpole", "real.truth=nominal", f"seed={seed}")
        changed = np.flatnonzero(~np.isclose(moved, nominal))
        assert 1 <= len(changed) <= 1 + (seed - 1) % 3 and set(changed) <= {0, 1, 2, 3, 12}, (seed, changed)


def test_corner_truths_put_every_parameter_in_one_of_its_priors_tails(compose, tmp_path):
    """real.truth=corner: seed 0 every parameter at 3 % of its range above the lower face (Cartpole's corner bed,
    docs/benchmarks.md); later seeds each parameter 1-5 % inside its lower or its upper face, the face drawn per
    parameter, reproducibly."""
    cartpole = ["task=Cartpole", "real.truth=corner"]
    low, high = np.array([p.range for p in compose(cartpole).task.parameters.values()], dtype=float).T
    np.testing.assert_allclose(_truth(compose, tmp_path / "c0", *cartpole, "seed=0"), low + 0.03 * (high - low))
    faces = []
    for seed in range(1, 6):
        cdf = (_truth(compose, tmp_path / f"c{seed}", *cartpole, f"seed={seed}") - low) / (high - low)
        depth = np.minimum(cdf, 1 - cdf)
        assert ((depth >= 0.01 - 1e-9) & (depth <= 0.05 + 1e-9)).all(), (seed, cdf)
        faces.append(cdf > 0.5)
    upper = np.array(faces)
    assert 0.2 < upper.mean() < 0.8 and len({tuple(row) for row in upper}) == 5  # both faces, a new corner each seed
    np.testing.assert_array_equal(_truth(compose, tmp_path / "again", *cartpole, "seed=2"),
                                  _truth(compose, tmp_path / "c2", *cartpole, "seed=2"))

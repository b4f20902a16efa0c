"""policy=replay: the pairs the spread is calibrated and checked on replay the real trajectories as they were executed
(no action noise), the training pairs with the noise."""

import pytest

from bayessim_exp.artifacts import RunDir
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow


def test_the_calibration_and_held_out_pairs_replay_the_real_actions_exactly(compose, tmp_path):
    cfg = compose(["task=Pendulum", "policy=replay", "debug=smoke", "collect.keep_trajectories=true", "rounds=1"])
    Pipeline(cfg, tmp_path).run()
    collected = RunDir(tmp_path).load(1, "collect")
    real = RunDir(tmp_path).load(1, "real")["traj"]["actions"]
    n, held_out = cfg.collect.trajectories, int(cfg.diagnostics.held_out_fraction * cfg.collect.trajectories)
    assert collected["exact"].tolist() == [False] * (n - 2 * held_out) + [True] * (2 * held_out)
    actions = collected["traj"]["actions"]
    replays_real = (actions[:, None] == real[None]).all(-1).all(-1).any(1)  # some real trajectory's actions, exactly
    assert replays_real.tolist() == collected["exact"].tolist()
    fitted = RunDir(tmp_path).load(1, "fit")
    assert fitted["held_out"]["count"] == held_out  # the last rows: exact replays

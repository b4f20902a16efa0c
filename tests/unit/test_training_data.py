"""inference/bayessim/training_data.py: which pooled rows calibrate the model's spread."""

import pytest

from bayessim_exp.errors import ConfigError
from bayessim_exp.inference.bayessim.training_data import calibration_rows
from bayessim_exp.pipeline import Pipeline


def test_the_spread_is_calibrated_on_the_latest_round_s_rows_or_on_every_round_s():
    latest = calibration_rows(10, 4, "latest")
    assert latest.tolist() == [False] * 6 + [True] * 4
    assert calibration_rows(10, 4, "all").all()
    assert calibration_rows(4, 4, "latest").all()  # round 1: its own rows are every row


def test_an_unknown_calibrate_on_is_refused_before_any_compute(compose, tmp_path):
    with pytest.raises(ConfigError, match="calibrate_on='first' not allowed; allowed: latest, all"):
        Pipeline(compose(["method.calibrate_on=first"]), tmp_path)

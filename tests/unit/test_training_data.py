"""inference/bayessim/training_data.py: which pooled rows calibrate the model's spread."""

import pytest

from bayessim_exp.errors import ConfigError
from bayessim_exp.inference.bayessim.method import BayesSimConfig
from bayessim_exp.inference.bayessim.training_data import calibration_rows


def test_the_spread_is_calibrated_on_the_latest_round_s_rows_or_on_every_round_s():
    latest = calibration_rows(10, 4, "latest")
    assert latest.tolist() == [False] * 6 + [True] * 4
    assert calibration_rows(10, 4, "all").all()
    assert calibration_rows(4, 4, "latest").all()  # round 1: its own rows are every row


def test_an_unknown_calibrate_on_is_refused():
    cfg = BayesSimConfig(proposal="prior", finetune=True, max_components=50, parameter_space="box",
                         combination="product", replay_tempering=True, on_guard="fallback", importance_draws=100_000,
                         escape="nearest", integrators=["model"], summary_error="replays", calibrate_on="first")
    with pytest.raises(ConfigError, match="calibrate_on='first' not allowed; allowed: latest, all"):
        cfg.validate()

"""The summary error model (inference/bayessim/summary_error.py): what it reads from a round's replays, the noise it
adds, and which round's simulations get it."""

import pytest
import torch

from bayessim_exp.errors import ConfigError
from bayessim_exp.inference.bayessim.method import BayesSim
from bayessim_exp.inference.bayessim.summary_error import SummaryError
from bayessim_exp.registry import parse_params


def test_no_feature_left_unexplained_is_no_error_model():
    assert SummaryError.from_variance(None) is None
    assert SummaryError.from_variance(torch.zeros(5, dtype=torch.float64)) is None


def test_the_noise_has_the_read_variance_in_its_features_and_none_elsewhere():
    error = SummaryError.from_variance(torch.tensor([0.0, 4.0, 0.0, 0.25], dtype=torch.float64))
    x = torch.arange(4, dtype=torch.float32).repeat(200_000, 1)
    noisy = error.add(x, torch.Generator().manual_seed(0))
    assert noisy.dtype == torch.float32
    assert torch.equal(noisy[:, [0, 2]], x[:, [0, 2]])
    torch.testing.assert_close(noisy[:, [1, 3]].double().std(0), torch.tensor([2.0, 0.5], dtype=torch.float64),
                               rtol=0.01, atol=0)
    assert error.modelled.tolist() == [False, True, False, True]
    assert error.record() == {"features": [1, 3], "std": [2.0, 0.5]}


def test_a_round_that_reads_no_feature_keeps_the_error_model_and_one_that_reads_some_replaces_it():
    """A round trained with a feature's noise need not read that feature's error again (its replays' whole residual
    need not lie beyond theirs)."""
    error = SummaryError.from_variance(torch.tensor([0.0, 4.0, 0.25, 0.0], dtype=torch.float64))
    assert error.carried(torch.zeros(4, dtype=torch.float64)).tolist() == [0.0, 4.0, 0.25, 0.0]
    read = torch.tensor([0.09, 0.0, 1.0, 0.0], dtype=torch.float64)
    assert error.carried(read).tolist() == read.tolist()


class _Rounds:
    """A round context whose condition outputs are given per round."""

    def __init__(self, round_, conditions):
        self.round, self.conditions = round_, conditions

    def output(self, stage, round_=None):
        assert stage == "condition"
        return self.conditions[round_]


def _method(mode):
    method = BayesSim.__new__(BayesSim)  # only the config is read
    method.cfg = type("Cfg", (), {"summary_error": mode})()
    return method


def test_round_r_simulates_with_what_round_r_minus_1_s_replays_left_unexplained():
    variance = torch.tensor([0.0, 0.09], dtype=torch.float64)
    conditions = {1: {"feature_error": variance}, 2: {"feature_error": torch.zeros(2, dtype=torch.float64)}}
    assert _method("replays")._summary_error(_Rounds(1, conditions)) is None  # round 1: nothing read yet
    torch.testing.assert_close(_method("replays")._summary_error(_Rounds(2, conditions)).std, variance.sqrt())
    assert _method("replays")._summary_error(_Rounds(3, conditions)) is None  # round 2 carried nothing on
    assert _method("none")._summary_error(_Rounds(2, conditions)) is None
    assert _method("replays")._summary_error(_Rounds(2, {1: {}})) is None  # a run recorded before the key


def test_an_unknown_summary_error_lists_the_allowed_ones():
    assert parse_params("method", {"name": "bayessim", "summary_error": "none"})[1].summary_error == "none"
    with pytest.raises(ConfigError, match="summary_error='learned' not allowed; allowed: replays, none"):
        parse_params("method", {"name": "bayessim", "summary_error": "learned"})

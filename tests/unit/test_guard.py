"""The guard flags worse-than-prior and miscalibrated posteriors, and passes a good one."""

from bayessim_exp.diagnostics.guard import check_posterior


def test_a_calibrated_informative_posterior_passes():
    report = check_posterior(2.5, {"0.5": 0.48, "0.9": 0.91})
    assert report.ok and report.to_dict() == {"ok": True, "warnings": []}


def test_worse_than_prior_is_flagged_with_what_to_try():
    report = check_posterior(-1.0, {"0.5": 0.5, "0.9": 0.9})
    assert not report.ok and len(report.warnings) == 1
    assert "worse than the prior" in report.warnings[0] and "probit" in report.warnings[0]


def test_zero_gain_is_flagged():
    assert not check_posterior(0.0, None).ok


def test_over_and_underconfidence_are_flagged_per_level():
    report = check_posterior(1.0, {"0.5": 0.2, "0.9": 0.99})
    assert [w.split(":")[0] for w in report.warnings] == ["overconfident", "underconfident"]


def test_nothing_measured_is_nothing_flagged():
    assert check_posterior(None, None).ok

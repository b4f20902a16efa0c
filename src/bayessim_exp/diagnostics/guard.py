"""The guard: flags a posterior that is worse than the prior or badly calibrated on held-out simulations.

Inputs are the held-out check every round computes: the mean log-density gain over the prior at
the held-out true parameters, mean of log q(theta_i | x_i) - log p(theta_i) (negative: the posterior
knows less than the prior, and domain randomization with it is worse than with the prior), and
the expected coverage of credible regions (diagnostics/coverage.py). Each finding is a sentence
saying what is wrong and what to try.
"""

from __future__ import annotations

import dataclasses

# coverage further than this below (overconfident) or above (underconfident) the nominal level L is
# flagged; never more than half the nominal miscoverage (1 - L) / 2, so 90 % regions must cover 85-95 %
COVERAGE_TOLERANCE = 0.1


@dataclasses.dataclass
class GuardReport:
    warnings: list[str]

    @property
    def ok(self) -> bool:
        return not self.warnings

    def to_dict(self) -> dict:
        return {"ok": self.ok, "warnings": list(self.warnings)}


def check_posterior(mean_gain: float | None, coverage: dict[str, float] | None,
                    tolerance: float = COVERAGE_TOLERANCE) -> GuardReport:
    """mean_gain: held-out mean log q - log p (nats); coverage: {level (str or float): fraction} of
    HPD regions on held-out simulations. Either may be None (not measured)."""
    warnings = []
    if mean_gain is not None and not mean_gain > 0:
        warnings.append(
            f"the posterior is worse than the prior on held-out simulations (mean log-density gain {mean_gain:+.2f} "
            "nats): do not randomize with it. Try the probit parameter space if box was set (method.parameter_space=probit; "
            "api.fit_posterior_model(..., probit=True)), model=mdnn_projected_diagonal, model.covariance=diagonal with fewer components, a summarizer that carries more "
            "information (corrdiff, waypoints), more simulations, or model=linear as a floor")
    for level, value in (coverage or {}).items():
        nominal = float(level)
        tol = min(tolerance, (1 - nominal) / 2)
        if value < nominal - tol:
            warnings.append(
                f"overconfident: {value:.0%} of held-out true parameters fall in the {nominal:.0%} credible region: "
                "the posterior is too narrow. Try an ensemble (model.ensemble=3, mdnn), stronger regularisation "
                "(weight_decay, smaller hidden layers), model.covariance=diagonal, more simulations, or "
                "method.parameter_space=probit if box was set")
        elif value > nominal + tol:
            warnings.append(
                f"underconfident: {value:.0%} of held-out true parameters fall in the {nominal:.0%} credible region: "
                "the posterior is wider than the data allow. Try more components, a larger network or more epochs "
                "(patience)")
    return GuardReport(warnings)

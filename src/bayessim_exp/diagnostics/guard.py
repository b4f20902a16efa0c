"""The guard: flags a round whose posterior is worse than what it started from, badly calibrated on held-out
simulations, or given by an unreliable importance-sampling estimate.

Inputs are what every round measures on its held-out simulations (the last
`diagnostics.held_out_fraction` of the round's own, drawn from the round's proposal):
- the mean log-density gain of the fitted q over the proposal, mean of log q(theta_i | x_i) - log p~(theta_i)
  (round 1: over the prior). Not above zero: the round's model knows nothing beyond the distribution its
  simulations came from, and domain randomization with it is no better than with that distribution;
- the expected coverage of its HPD regions (diagnostics/coverage.py) against the nominal level L, within
  min(COVERAGE_TOLERANCE, (1 - L) / 2) (90 % regions: 85-95 %) widened by the estimate's own sampling error
  (SAMPLING_Z binomial standard errors over the held-out pairs), so a calibrated model checked on few pairs
  is not flagged by chance;
- the effective sample size of the posterior given the real data, where it is an importance-sampling
  estimate (no closed form): below MIN_EFFECTIVE_SAMPLES its density and draws rest on a handful of points;
- where the real data lie among the simulations the model was trained on (extrapolation.py): a real summary
  farther from them than all but a share alpha / n of the held-out simulations gets an extrapolated posterior;
  and one with more summary features outside the training simulations' range than all but that share of the
  held-out ones (mismatch.py's summaries_outside). The second sees what the first's ridge predictions can miss
  where summaries are far from linear in the parameters: a pendulum whose length is 5 prior standard deviations
  out put 2 to 14 features outside the range (p = 0.001) at distances of p = 0.06 to 0.2, and its posteriors
  held the length at the prior's (-188 to -1741 nats at the truth; docs/benchmarks.md); the range test flagged no
  case of the foreign-dynamics benchmark, other integrators included. (BayesSim leaves both out where the real
  trajectories were replayed and the posterior widened, to a temperature below 1, by what the replays leave
  unexplained: that measures the same difference near the posterior);
- where asked (diagnostics.local_sets), the coverage where the real data put the posterior (local_coverage.py),
  in the same band as the held-out coverage: below it the model is off near the real data even if it is
  calibrated on average.
Each finding is a sentence saying what is wrong and what to try. Underconfidence is a finding but not a
failure: a posterior wider than the data allow is still safe to randomize with (the round's action,
method.on_guard, follows failures only). The last two findings say where the real data lie, not how good the model
is on its own simulations (`near_real_data_only`): more simulations where the posterior points cure them, so a
method may still propose from such a posterior while handing on an earlier one.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

COVERAGE_TOLERANCE = 0.1
SAMPLING_Z = 1.645  # one-sided 5 % at a band edge; a calibrated model sits mid-band, far from it
MIN_EFFECTIVE_SAMPLES = 200
Action = Literal["warn", "fallback", "stop"]  # method.on_guard's choices


@dataclasses.dataclass
class GuardReport:
    warnings: list[str]
    failed: bool = False  # a finding that makes the posterior unsafe to randomize with (all but underconfidence)
    # every failure says the model was not trained or checked where the real data lie (extrapolation, coverage near
    # them), none that it is wrong on its own held-out simulations
    near_real_data_only: bool = False

    @property
    def ok(self) -> bool:
        return not self.warnings

    def to_dict(self) -> dict:
        return {"ok": self.ok, "failed": self.failed, "near_real_data_only": self.near_real_data_only,
                "warnings": list(self.warnings)}


def coverage_band(level: float, count: int, tolerance: float = COVERAGE_TOLERANCE) -> tuple[float, float]:
    """The held-out coverage of level-L regions that passes, from `count` held-out pairs."""
    half = min(tolerance, (1 - level) / 2) + SAMPLING_Z * math.sqrt(level * (1 - level) / max(count, 1))
    return level - half, level + half


def _outside_warning(far: list[int], evidence: str, advice: str) -> str:
    """The finding that real trajectories `far` lie where the model has no training simulations, with what shows it."""
    return (f"the real data lie outside the simulations the model was trained on: real trajectories {far} {evidence}: "
            f"the posterior there is an extrapolation. {advice}")


def check_posterior(mean_gain: float | None, coverage: dict[str, float] | None, count: int,
                    baseline: str = "prior", effective_samples: float | None = None,
                    tolerance: float = COVERAGE_TOLERANCE, local: dict | None = None,
                    extrapolation: dict | None = None, outside_range: dict | None = None) -> GuardReport:
    """mean_gain: held-out mean log q - log of `baseline` (the round's proposal; nats); coverage: {level (str
    or float): fraction} of HPD regions on `count` held-out simulations; effective_samples: of an
    importance-sampled posterior (None: closed form); local: local_coverage's record; extrapolation:
    inputs_outside's record; outside_range: summaries_outside's record with `flagged`, the real summaries
    below its alpha / n. Any may be None (not measured)."""
    # failures on the model's own held-out simulations, and failures where the real data lie
    warnings, model_failed, near_real = [], False, False
    if mean_gain is not None and not (math.isfinite(mean_gain) and mean_gain > 0):  # infinite: a density of zero
        model_failed = True
        warnings.append(
            f"the posterior is worse than the {baseline} on held-out simulations (mean log-density gain "
            f"{mean_gain:+.2f} nats): do not randomize with it. Try the probit parameter space if box was set "
            "(method.parameter_space=probit; api.fit_posterior_model(..., probit=True)), model=mdnn_projected_diagonal, "
            "model.covariance=diagonal with fewer components, a summarizer that carries more information (corrdiff, "
            "waypoints), more simulations, or model=linear as a floor")
    for level, value in (coverage or {}).items():
        low, high = coverage_band(float(level), count, tolerance)
        if value < low:
            model_failed = True
            warnings.append(
                f"overconfident: {value:.0%} of held-out true parameters fall in the {float(level):.0%} credible "
                f"region (passes from {low:.0%}): the posterior is too narrow. Try an ensemble (model.ensemble=3, "
                "mdnn), stronger regularisation (weight_decay, smaller hidden layers), model.covariance=diagonal, "
                "more simulations, or method.parameter_space=probit if box was set")
        elif value > high:
            warnings.append(
                f"underconfident: {value:.0%} of held-out true parameters fall in the {float(level):.0%} credible "
                f"region (passes up to {high:.0%}): the posterior is wider than the data allow. Try more "
                "components, a larger network or more epochs (patience)")
    for level, value in ((local or {}).get("hpd") or {}).items():
        low = coverage_band(float(level), local["count"], tolerance)[0]
        if value < low:
            near_real = True
            warnings.append(
                f"overconfident near the real data: {value:.0%} of parameters drawn from the posterior fall in the "
                f"{float(level):.0%} credible region once a trajectory simulated at them is added to the real ones "
                f"(passes from {low:.0%}): the model is off where the real data lie, which the held-out simulations "
                "(drawn from the round's proposal) average away. Try more simulations, an ensemble (model.ensemble=3), "
                "a summarizer that carries more information, or method.proposal=prior")
    if extrapolation is not None and extrapolation["flagged"]:
        near_real = True
        far = extrapolation["flagged"]
        warnings.append(_outside_warning(
            far, f"are farther from them (squared distances {[round(extrapolation['distance'][i], 1) for i in far]}, "
            f"held-out median {extrapolation['held_out_median']:.1f}) than all but "
            f"{[extrapolation['p_value'][i] for i in far]} of the held-out simulations",
            "A real system in the joint tail of independent ranges (every mass scaled alike) needs a prior that holds "
            "it; else try more simulations, policy=replay with the real actions, or model.project_inputs=false"))
    if outside_range is not None and outside_range["flagged"]:
        near_real = True
        far = outside_range["flagged"]
        warnings.append(_outside_warning(
            far, f"have {[outside_range['features_outside'][i] for i in far]} summary features outside the training "
            f"simulations' range, more than all but {[outside_range['p_value'][i] for i in far]} of the held-out "
            "simulations",
            "Try a prior that holds the real system, more simulations, or policy=replay with the real actions"))
    if effective_samples is not None and effective_samples < MIN_EFFECTIVE_SAMPLES:
        model_failed = True
        warnings.append(
            f"the posterior given the real data has no closed form and its importance-sampling estimate rests on "
            f"{effective_samples:.0f} effective draws (< {MIN_EFFECTIVE_SAMPLES}): its density and draws are not "
            "reliable. Try method.proposal=truncated, fewer mixture components (model.components) or a model of "
            "one Gaussian per network (mdnn_projected_gaussian_ensemble)")
    return GuardReport(warnings, model_failed or near_real, near_real and not model_failed)

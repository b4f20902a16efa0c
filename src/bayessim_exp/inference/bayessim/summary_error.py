"""A summary error model: features the simulator cannot reproduce near the posterior, and noise that teaches q so.

A real system differs from the simulator in a few summary features (a sensor's offset, friction the model lacks
showing in the late steps) as often as in all of them. The replays' tempering (replay_tempering.py) widens the
posterior in every direction until those features' implied parameters fit inside it: a bias in two features of
eighty cost most of the information on benchmarks/summary_bias.py. The error model instead reads, feature by
feature, what the replays of round r's posterior leave unexplained in the real summaries
(diagnostics/replayed_check.py: `feature_error`, a variance per feature where the real residual lies beyond every
replay's and beyond a Bonferroni bound on their scale), and round r + 1 adds Gaussian noise of those variances to
every simulated summary its model is trained and checked on (robust NPE's noise model, Gaussian, with the
variances read from the replays rather than learned): q then learns how little those features say, the
product's temperature sees the same noise, the replays' widening answers only what the other features leave
unexplained (replayed_check reads the parameters from them), and the features the simulator does reproduce
keep their weight. The mismatch verdict stays on the simulations as simulated: a misread sensor is still a
mismatch. docs/statistics.md has the measurements.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import torch

Mode = Literal["replays", "none"]  # method.summary_error's choices


@dataclasses.dataclass
class SummaryError:
    """Per-feature standard deviations [F] of the noise added to simulated summaries (0 where none)."""

    std: torch.Tensor

    @classmethod
    def from_variance(cls, variance: torch.Tensor | None) -> SummaryError | None:
        """The error model of a check's `feature_error` variances, or None where every one is 0 (or no check)."""
        if variance is None or not bool((variance > 0).any()):
            return None
        return cls(variance.double().sqrt())

    def carried(self, read: torch.Tensor) -> torch.Tensor:
        """The next round's variances [F]: a check's `feature_error` where it read any feature, else this model's.
        A check reads none where the real summary's whole residual lies within the replays' (replayed_check), as it
        can for replays of a posterior trained with this noise: no evidence that the error is gone (a glitch read in
        round 1 was dropped from round 3 so: docs/statistics.md). Where it reads some, the read replaces the model:
        kept as well, the features each round reads by chance would pile up."""
        return read if bool((read > 0).any()) else (self.std**2).to(read)

    def add(self, x: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """x [..., F] with independent noise of `std` in each feature, drawn from `generator` (on the CPU)."""
        noise = torch.randn(x.shape, generator=generator, dtype=torch.float64) * self.std
        return x + noise.to(x.device, x.dtype)

    @property
    def modelled(self) -> torch.Tensor:
        """[F] bool: the features with noise."""
        return self.std > 0

    def record(self) -> dict:
        """What results.json keeps: the features with noise and its standard deviations."""
        features = torch.nonzero(self.modelled).flatten()
        return {"features": features.tolist(), "std": self.std[features].tolist()}

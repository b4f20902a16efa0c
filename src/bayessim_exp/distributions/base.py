"""The contract of every distribution the project hands out: priors, posteriors, proposals.

Call sites (the pipeline, diagnostics, plots, RL's domain randomization) use only these members and
never switch on the concrete class:

    dim, low, high        the support box (None where unbounded)
    sample(shape, generator=None) -> float64 [*shape, D]
    log_prob(theta)       -> float64 [...], -inf outside the support
    mean, stddev          float64 [D]; Monte Carlo with a fixed seed unless a subclass knows them exactly
    superlevel_box(level) a box around {log_prob >= level}, or None (truncated proposals sample within it)
    effective_sample_size the draws an importance-sampling estimate rests on; None where exact
    save(path), load(path)        a data file (data_files.py), never a pickle
"""

from __future__ import annotations

import contextlib
import functools
from pathlib import Path

import torch

from ..data_files import load_state, save_state
from ..errors import DataFileError

# draws behind Monte Carlo moments: the standard error of the mean is stddev / 140
_MOMENT_DRAWS = 20_000
_MOMENT_SEED = 12345


class ParameterDistribution:
    low: torch.Tensor | None = None
    high: torch.Tensor | None = None

    @property
    def dim(self) -> int:
        raise NotImplementedError

    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        raise NotImplementedError

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def superlevel_box(self, level: float) -> tuple[torch.Tensor, torch.Tensor] | None:
        """A box (low, high) in parameter units holding every theta with log_prob(theta) >= level; None
        where none is known (here, and for every distribution that does not say otherwise)."""
        return None

    @property
    def effective_sample_size(self) -> float | None:
        """Where the distribution is an importance-sampling estimate, the effective number of draws it
        rests on (the guard refuses too few); None for distributions known exactly."""
        return None

    @functools.cached_property
    def _moments(self) -> tuple[torch.Tensor, torch.Tensor]:
        draws = self.sample((_MOMENT_DRAWS,), generator=torch.Generator().manual_seed(_MOMENT_SEED)).double()
        return draws.mean(0), draws.std(0)

    @property
    def mean(self) -> torch.Tensor:
        return self._moments[0]

    @property
    def stddev(self) -> torch.Tensor:
        return self._moments[1]

    def save(self, path: str | Path) -> None:
        save_state(self, path)

    @staticmethod
    def load(path: str | Path, trusted: bool = False) -> ParameterDistribution:
        """trusted=True also reads a file in the old pickle format, running any code it holds."""
        name = "bayessim_exp.distributions.base.ParameterDistribution"
        dist = load_state(path, trusted, convert_hint=f"{name}.load({str(path)!r}, trusted=True).save({str(path)!r})")
        if not isinstance(dist, ParameterDistribution):
            raise DataFileError(f"{path} holds a {type(dist).__name__}, not a ParameterDistribution")
        return dist


@contextlib.contextmanager
def seeded_by(generator: torch.Generator | None):
    """Run code that draws from torch's global generator reproducibly from `generator` (when given),
    leaving the global state as it was: for samplers (flows) that take no generator of their own."""
    if generator is None:
        yield
        return
    seed = int(torch.randint(0, 2**62, (1,), generator=generator))
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        yield

"""The contract of every distribution the project hands out: priors, posteriors, proposals.

Call sites (the pipeline, diagnostics, plots, RL's domain randomization) use only these members and
never switch on the concrete class:

    dim, low, high        the support box (None where unbounded)
    sample(shape, generator=None) -> float64 [*shape, D]
    log_prob(theta)       -> float64 [...], -inf outside the support
    mean, stddev          float64 [D]; Monte Carlo with a fixed seed unless a subclass knows them exactly
    quantiles(levels)     float64 [L, D] per-parameter quantiles; exact for independent ones, else from those draws
    superlevel_box(level) a box around {log_prob >= level}, or None (truncated proposals sample within it)
    effective_sample_size the draws an importance-sampling estimate rests on; None where exact
    gaussian_factor()     the Gaussian the density is on its support, for the SNPE-A correction's closed form
    as_gaussian_mixture() itself where it is a Gaussian mixture over R^D, else None
    restricts(prior)      whether it is the prior restricted to a region (no correction needed)
    in_probit_space()     the distribution over probit space it maps back, or None
    independent           marginal_cdf, marginal_icdf, log_marginal answer (priors: probit space)
    save(path), load(path)        a data file (data_files.py), never a pickle
"""

from __future__ import annotations

import contextlib
import functools
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from ..data_files import load_state, save_state
from ..errors import DataFileError

# draws behind Monte Carlo moments: the standard error of the mean is stddev / 140
_MOMENT_DRAWS = 20_000
_MOMENT_SEED = 12345
# the per-parameter quantiles results.json and the exports give (5, 50 and 95 %)
QUANTILE_LEVELS = (0.05, 0.5, 0.95)
# gaussian_factor's answer where the density is neither a Gaussian's nor constant on its support
NOT_GAUSSIAN = "not Gaussian"

if TYPE_CHECKING:
    from .mixture import GaussianMixture


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

    def gaussian_factor(self) -> tuple[torch.Tensor, torch.Tensor] | None | str:
        """(mean, cov) of the Gaussian the density equals on its support up to a constant, None where it is
        constant there, NOT_GAUSSIAN otherwise: the SNPE-A correction is in closed form for the first two."""
        return NOT_GAUSSIAN

    def as_gaussian_mixture(self) -> GaussianMixture | None:
        """Itself where it is a Gaussian mixture over R^D (products and moments in closed form), else None."""
        return None

    def restricts(self, prior: ParameterDistribution) -> bool:
        """Whether its density is prior's times a constant wherever it is positive: a model trained on its
        draws needs no proposal correction (the prior itself is handled by the caller)."""
        return False

    def in_probit_space(self) -> ParameterDistribution | None:
        """The distribution over u = probit(theta) (distributions/probit.py) that this one maps back to
        parameter units; None where it is not defined that way."""
        return None

    # independent distributions (the priors) answer the per-coordinate questions below: probit space needs them
    independent = False

    def marginal_cdf(self, theta: torch.Tensor) -> torch.Tensor:
        """F_d(theta_d) per coordinate: [..., D]."""
        raise NotImplementedError(f"{type(self).__name__} has no independent marginals")

    def marginal_icdf(self, c: torch.Tensor) -> torch.Tensor:
        """F_d^-1(c_d) per coordinate: [..., D]."""
        raise NotImplementedError(f"{type(self).__name__} has no independent marginals")

    def log_marginal(self, theta: torch.Tensor) -> torch.Tensor:
        """log p_d(theta_d) per coordinate: [..., D]."""
        raise NotImplementedError(f"{type(self).__name__} has no independent marginals")

    @property
    def peak(self) -> torch.Tensor:
        """A point of largest density (of an independent distribution, on its support)."""
        raise NotImplementedError(f"{type(self).__name__} has no independent marginals")

    def _moment_draws(self) -> torch.Tensor:
        return self.sample((_MOMENT_DRAWS,), generator=torch.Generator().manual_seed(_MOMENT_SEED)).double()

    @functools.cached_property
    def _moments(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Mean, std and the QUANTILE_LEVELS quantiles of one set of draws (sampling may cost: done once)."""
        draws = self._moment_draws()
        return draws.mean(0), draws.std(0), _quantiles(draws, QUANTILE_LEVELS)

    def quantiles(self, levels: tuple[float, ...] = QUANTILE_LEVELS) -> torch.Tensor:
        """Per-parameter quantiles [len(levels), D]: exact (marginal_icdf) for independent distributions, else from
        the draws behind the Monte Carlo moments."""
        levels = tuple(float(q) for q in levels)
        if not all(0.0 <= q <= 1.0 for q in levels):
            raise ValueError(f"quantile levels must lie in [0, 1], got {levels}")
        if self.independent:
            c = torch.tensor(levels, dtype=torch.float64)[:, None].expand(len(levels), self.dim)
            return self.marginal_icdf(c.contiguous()).double()
        if levels == QUANTILE_LEVELS:
            return self._moments[2]
        return _quantiles(self._moment_draws(), levels)

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


def _quantiles(draws: torch.Tensor, levels: tuple[float, ...]) -> torch.Tensor:
    # numpy: torch.quantile refuses inputs above 2**24 values (20,000 draws of 839 parameters)
    return torch.from_numpy(np.quantile(draws.numpy(), levels, axis=0))


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

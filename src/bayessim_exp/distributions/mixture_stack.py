"""Gaussian mixtures of one size, S of them stacked: the simulated sets' tempered products that the product's
temperature is fitted on (inference/bayessim/set_calibration.py), read together.

Each set's own HPD level needs draws of its posterior and their densities. One `GaussianMixture` per set made that
a loop of small tensor operations per set and temperature, most of the condition stage
(benchmarks/condition_speed.py); here every set's draws and densities are a few batched operations, on the
run's device. A member is the `GaussianMixture` with the same
log weights, means and covariances (mapped back from probit space as `ProbitPosterior` maps it where `transform` is
set): the same formulas, and `noise` consumes a generator exactly as the member's `sample` does, so the levels read
here are those read set by set, to rounding.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Sequence

import torch

from .box import restrict_log_prob
from .mixture import GaussianMixture, _cholesky, is_diagonal
from .probit import ProbitTransform

_LOG_2PI = math.log(2 * math.pi)
# doubles the draws and densities of one chunk of members hold at once: a few members at a time on a CPU, whose
# caches a larger chunk outgrows (at ShadowHand's size, 20 members at once took 2.5 to 3.6 times as long as 2 at a
# time on the 2-core development machine), and every member on a GPU, where one operation over them all saves the time
_CHUNK_ELEMENTS_CPU, _CHUNK_ELEMENTS_GPU = 2**20, 2**26


class MixtureStack:
    """S mixtures of K Gaussians over R^D: log weights [S, K], means [S, K, D], covariances and their lower
    Cholesky factors [S, K, D, D], float64, on the device they are given on; `transform`: the probit transform the
    members are mapped back to parameter units with, or None for mixtures in parameter units."""

    transform: ProbitTransform | None = None

    def __init__(self, logits: torch.Tensor, means: torch.Tensor, covs: torch.Tensor):
        self.log_weights = torch.log_softmax(logits.double(), -1)
        self.means = means.double()
        covs = 0.5 * (covs.double() + covs.double().transpose(-1, -2))
        if not torch.isfinite(covs.sum()):  # one pass, where isfinite(covs).all() is three over a stack this size
            raise ValueError("a mixture component's covariance is not finite")
        factor, info = torch.linalg.cholesky_ex(covs)
        for s in torch.nonzero((info != 0).any(-1)).flatten().tolist():  # a member's jitter, as GaussianMixture adds it
            covs[s], factor[s] = _cholesky(covs[s])
        self.covs, self.scale_tril = covs, factor

    @classmethod
    def of(cls, mixtures: Sequence[GaussianMixture]) -> MixtureStack | None:
        """The mixtures stacked, their Cholesky factors kept; None where their sizes differ."""
        if len({m.means.shape for m in mixtures}) != 1:
            return None
        stack = cls.__new__(cls)
        stack.log_weights = torch.stack([m.log_weights for m in mixtures])
        stack.means = torch.stack([m.means for m in mixtures])
        stack.covs = torch.stack([m.covs for m in mixtures])
        stack.scale_tril = torch.stack([m.scale_tril for m in mixtures])
        return stack

    def mapped(self, transform: ProbitTransform) -> MixtureStack:
        """The members mapped back from probit space (ProbitPosterior)."""
        out = copy.copy(self)
        out.transform = transform
        return out

    @functools.cached_property
    def precisions(self) -> torch.Tensor:
        """The components' inverse covariances [S, K, D, D]."""
        return torch.cholesky_inverse(self.scale_tril)

    @functools.cached_property
    def log_dets(self) -> torch.Tensor:
        """The log determinants of the components' covariances [S, K]."""
        return 2 * torch.log(torch.diagonal(self.scale_tril, dim1=-2, dim2=-1)).sum(-1)

    @functools.cached_property
    def diagonal_std(self) -> torch.Tensor | None:
        """The components' standard deviations [S, K, D] where every covariance is diagonal (a diagonal model's
        sets: draws and densities elementwise, D per point instead of D^2), else None."""
        return torch.diagonal(self.scale_tril, dim1=-2, dim2=-1) if is_diagonal(self.scale_tril) else None

    @functools.cached_property
    def _weights(self) -> torch.Tensor:
        return self.log_weights.exp().cpu()

    def __len__(self) -> int:
        return self.means.shape[0]

    @property
    def dim(self) -> int:
        return self.means.shape[-1]

    def to(self, device: torch.device | str) -> MixtureStack:
        """The stack with its mixtures' tensors on `device` (the transform stays on the CPU)."""
        out = type(self).__new__(type(self))
        out.log_weights, out.means, out.covs, out.scale_tril = (
            t.to(device) for t in (self.log_weights, self.means, self.covs, self.scale_tril))
        out.transform = self.transform
        return out

    def noise(self, member: int, count: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """What the member's `sample((count,), generator)` draws from the generator, a CPU one: the components
        [count] and the standard normal noise [count, D]."""
        comp = torch.multinomial(self._weights[member], count, replacement=True, generator=generator)
        return comp, torch.randn(count, self.dim, dtype=torch.float64, generator=generator)

    def draws(self, comp: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        """Every member's draws [S, N, D] on the CPU from its components comp [S, N] and noise eps [S, N, D]
        (`noise`): mean + L eps of each draw's component, in parameter units where `transform` is set."""
        device = self.means.device
        out = torch.cat([self._component_draws(s, c, e) for s, c, e in
                         self._chunks(comp.shape[1] * self.dim, comp.to(device), eps.to(device))]).cpu()
        return out if self.transform is None else self.transform.from_probit(out)

    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        """Each member's log density at its own points theta [S, N, D] on the CPU: [S, N] (-inf outside the
        transform's box)."""
        theta = theta.double()
        u = theta if self.transform is None else self.transform.to_probit(theta)
        k = self.log_weights.shape[1]
        lp = torch.cat([self._mixture_log_prob(s, points) for s, points in
                        self._chunks(k * u.shape[1], u.to(self.means.device))]).cpu()
        if self.transform is None:
            return lp
        return restrict_log_prob(lp + self.transform.log_abs_det_jacobian(theta, u), theta, self.transform.low,
                                 self.transform.high)

    def _component_draws(self, s: slice, comp: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        rows = torch.arange(comp.shape[0], device=comp.device)[:, None]
        if self.diagonal_std is not None:
            return self.means[s][rows, comp] + self.diagonal_std[s][rows, comp] * eps
        return self.means[s][rows, comp] + (self.scale_tril[s][rows, comp] @ eps.unsqueeze(-1)).squeeze(-1)

    def _mixture_log_prob(self, s: slice, u: torch.Tensor) -> torch.Tensor:
        """GaussianMixture.log_prob of members s at their points u [s, N, D]: one triangular solve per component
        (a division where the covariances are diagonal)."""
        diff = u.transpose(-1, -2).unsqueeze(1) - self.means[s].unsqueeze(-1)  # [s, K, D, N]
        if self.diagonal_std is not None:
            z = diff / self.diagonal_std[s].unsqueeze(-1)
        else:
            z = torch.linalg.solve_triangular(self.scale_tril[s], diff, upper=False)
        half_logdet = torch.log(torch.diagonal(self.scale_tril[s], dim1=-2, dim2=-1)).sum(-1)
        component = -0.5 * (z**2).sum(-2) - half_logdet[..., None] - 0.5 * self.dim * _LOG_2PI  # [s, K, N]
        return torch.logsumexp(self.log_weights[s, :, None] + component, 1)

    def _chunks(self, per_member: int, *tensors: torch.Tensor):
        """(slice, *tensors[slice]) over the members, in chunks of at most the device's budget of `per_member` x D
        doubles each."""
        budget = _CHUNK_ELEMENTS_CPU if self.means.device.type == "cpu" else _CHUNK_ELEMENTS_GPU
        step = max(1, budget // (per_member * self.dim))
        for start in range(0, len(self), step):
            s = slice(start, start + step)
            yield s, *(t[s] for t in tensors)

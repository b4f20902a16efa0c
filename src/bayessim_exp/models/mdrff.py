"""MDRFF: a mixture density head on random Fourier features of the summaries (Ramos et al. 2019).

The features phi(x) = [cos(W x), sin(W x)] / sqrt(m) of the standardised summaries approximate a
shift-invariant kernel k(x, x') = E_w cos(w . (x - x')) (Rahimi and Recht 2007): RBF for
w ~ N(0, I / l^2), Matern nu for w ~ multivariate Student-t with 2 nu degrees of freedom scaled by
1 / l. Quasi-random frequencies (scrambled Halton points through the inverse CDFs) cover the
spectral density more evenly than i.i.d. draws. The frequencies are fixed; only the layers on
top (optional hidden layers, then the mixture head shared with MDNN) and an optional embedding in
front (learned summaries, as for MDNN) are trained.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np
import torch
from scipy import stats
from torch import nn

from ..data_files import data_class
from ..errors import ConfigError
from .base import Standardizer, TrainConfig
from .mdnn import ACTIVATIONS, MDNN, Activation, Covariance, MemberNetworks, MixtureHead, input_projection
from .spread import SpreadScale

# kernel name -> degrees of freedom of the Student-t spectral density (None: Gaussian, the RBF)
KERNELS = {"rbf": None, "matern12": 1.0, "matern32": 3.0, "matern52": 5.0}
Kernel = Literal["rbf", "matern12", "matern32", "matern52"]  # KERNELS' keys


@data_class
@dataclasses.dataclass
class MdrffConfig(TrainConfig):
    features: int  # random Fourier features (cos and sin of features / 2 frequencies)
    kernel: Kernel
    lengthscale: float  # in units of the standardised summaries
    quasi_random: bool  # scrambled Halton frequencies instead of i.i.d. draws
    components: int
    covariance: Covariance
    hidden: list[int]  # layers between features and head; [] is BayesSim's linear head
    activation: Activation  # of the hidden layers

    def validate(self) -> None:
        super().validate()
        if self.components < 1:
            raise ConfigError(f"components must be an integer >= 1, got {self.components}")
        if any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must list positive layer sizes, got {self.hidden}")
        if self.features < 2 or self.features % 2:
            raise ConfigError(f"features must be an even integer >= 2, got {self.features}")
        if not self.lengthscale > 0:
            raise ConfigError(f"lengthscale must be > 0, got {self.lengthscale}")


def spectral_frequencies(in_dim: int, count: int, kernel: str, lengthscale: float, quasi_random: bool,
                         seed: int) -> torch.Tensor:
    """`count` frequencies [count, in_dim] drawn from the kernel's spectral density."""
    if quasi_random:
        u = stats.qmc.Halton(in_dim + 1, scramble=True, seed=seed).random(count)
    else:
        u = np.random.default_rng(seed).random((count, in_dim + 1))
    u = np.clip(u, 1e-9, 1 - 1e-9)
    w = stats.norm.ppf(u[:, :in_dim])
    dof = KERNELS[kernel]
    if dof is not None:  # Student-t: a Gaussian over sqrt(chi2_dof / dof)
        w = w / np.sqrt(stats.chi2.ppf(u[:, in_dim], dof) / dof)[:, None]
    return torch.as_tensor(w / lengthscale, dtype=torch.float32)


class RandomFourierFeatures(nn.Module):
    def __init__(self, in_dim: int, features: int):
        super().__init__()
        self.register_buffer("frequencies", torch.zeros(features // 2, in_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        proj = x @ self.frequencies.T
        return torch.cat([torch.cos(proj), torch.sin(proj)], -1) / math.sqrt(self.frequencies.shape[0])


@data_class
class MDRFF(MDNN):
    """MDNN's training, conditioning and state handling around a random-Fourier-feature body."""

    def __init__(self, cfg: MdrffConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None):
        self.cfg, self.theta_dim, self.x_dim = cfg, theta_dim, x_dim
        self.embedding = embedding if embedding is not None else nn.Identity()
        self.projection = input_projection(cfg, theta_dim, x_dim, embedding)
        with torch.no_grad():
            self.feature_in_dim = self.embedding(torch.zeros(2, x_dim if self.projection is None else theta_dim)).shape[-1]
        self.rff = RandomFourierFeatures(self.feature_in_dim, cfg.features)
        # MDNN's loss and conditioning with one member behind the (embedding, random features) front
        self.embedding = nn.Sequential(self.embedding, self.rff)
        self.head = MixtureHead(theta_dim, cfg.components, cfg.covariance == "full")
        self.members = MemberNetworks(1, cfg.features, cfg.hidden, ACTIVATIONS[cfg.activation], self.head.width)
        self.x_norm, self.theta_norm, self.spread = Standardizer(x_dim), Standardizer(theta_dim), SpreadScale(theta_dim)
        self.net = nn.ModuleDict({"embedding": self.embedding, "members": self.members, "head": self.head,
                                  "x_norm": self.x_norm, "theta_norm": self.theta_norm, "spread": self.spread,
                                  **({} if self.projection is None else {"projection": self.projection})})

    def fit(self, theta: torch.Tensor, x: torch.Tensor, *, seed: int, label: str = "", on_epoch=None,
            calibration_rows: torch.Tensor | None = None, calibration_only: torch.Tensor | None = None) -> dict:
        if not self.fitted:  # frequencies are drawn once, with the first fit's seed, and then kept
            c = self.cfg
            self.rff.frequencies.copy_(spectral_frequencies(self.feature_in_dim, c.features // 2, c.kernel, c.lengthscale,
                                                            c.quasi_random, seed))
        return super().fit(theta, x, seed=seed, label=label, on_epoch=on_epoch, calibration_rows=calibration_rows,
                           calibration_only=calibration_only)


def mdrff(cfg: MdrffConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None) -> MDRFF:
    return MDRFF(cfg, theta_dim, x_dim, embedding)

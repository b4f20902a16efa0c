"""MDNN: a mixture density network q(theta | x) with full- or diagonal-covariance components.

Inputs and targets are standardised with statistics of the first training set; components
are parameterised by the upper Cholesky factor U of their precision (positive diagonal via
exp), so that log N(theta; mu, (U^T U)^-1) = sum log diag U - |U (theta - mu)|^2 / 2 - D/2 log 2pi.
"""

from __future__ import annotations

import dataclasses
import math

import torch
from torch import nn

from ..distributions.mixture import GaussianMixture
from ..errors import ConfigError
from ..registry import register
from .base import StandardizedDensityModel, Standardizer, TrainConfig
from .projection import RidgeProjection

ACTIVATIONS = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU, "silu": nn.SiLU}


@dataclasses.dataclass
class MdnnConfig(TrainConfig):
    components: int
    hidden: list[int]
    activation: str
    covariance: str  # full | diagonal

    def validate(self) -> None:
        super().validate()
        if self.components < 1:
            raise ConfigError(f"components must be an integer >= 1, got {self.components}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must be a non-empty list of positive layer sizes, got {self.hidden}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"activation {self.activation!r} not allowed; allowed: {', '.join(ACTIVATIONS)}")
        if self.covariance not in ("full", "diagonal"):
            raise ConfigError(f"covariance {self.covariance!r} not allowed; allowed: full, diagonal")


def input_projection(cfg: TrainConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None) -> RidgeProjection | None:
    if not cfg.project_inputs:
        return None
    if embedding is not None:
        raise ConfigError("project_inputs replaces the summaries by linear predictions; it cannot follow a learned "
                          "embedding (summarizer=learned): set model.project_inputs=false")
    return RidgeProjection(x_dim, theta_dim)


class MixtureHead(nn.Module):
    """Features -> (logits [K], means [K, D], precision factors U [K, D, D])."""

    def __init__(self, in_dim: int, dim: int, components: int, full: bool):
        super().__init__()
        self.dim, self.k, self.full = dim, components, full
        self.n_off = dim * (dim - 1) // 2 if full else 0
        self.out = nn.Linear(in_dim, components * (1 + 2 * dim + self.n_off))
        self.register_buffer("triu", torch.triu_indices(dim, dim, offset=1), persistent=False)

    def forward(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        k, d = self.k, self.dim
        out = self.out(h)
        logits, means, log_diag, off = torch.split(out, [k, k * d, k * d, k * self.n_off], -1)
        U = torch.diag_embed(torch.exp(log_diag.reshape(-1, k, d).clamp(-12, 12)))
        if self.full:
            upper = torch.zeros_like(U)
            upper[:, :, self.triu[0], self.triu[1]] = off.reshape(-1, k, self.n_off)
            U = U + upper
        return logits, means.reshape(-1, k, d), U


def mixture_nll(logits: torch.Tensor, means: torch.Tensor, U: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    z = (U @ (theta[:, None, :] - means).unsqueeze(-1)).squeeze(-1)
    log_det = torch.log(torch.diagonal(U, dim1=-2, dim2=-1)).sum(-1)
    comp = log_det - 0.5 * (z**2).sum(-1) - 0.5 * means.shape[-1] * math.log(2 * math.pi)
    return -torch.logsumexp(torch.log_softmax(logits, -1) + comp, -1)


class MDNN(StandardizedDensityModel):
    """`embedding` (optional): a trainable module in front of the network, trained jointly
    (learned summaries); it maps standardised summaries [N, x_dim] to features [N, E]."""

    def __init__(self, cfg: MdnnConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None):
        self.cfg, self.theta_dim, self.x_dim = cfg, theta_dim, x_dim
        act = ACTIVATIONS[cfg.activation]
        self.embedding = embedding if embedding is not None else nn.Identity()
        self.projection = input_projection(cfg, theta_dim, x_dim, embedding)
        with torch.no_grad():
            width = self.embedding(torch.zeros(2, x_dim if self.projection is None else theta_dim)).shape[-1]
        layers = []
        for h in cfg.hidden:
            layers += [nn.Linear(width, h), act()]
            width = h
        self.body = nn.Sequential(self.embedding, *layers)
        self.head = MixtureHead(width, theta_dim, cfg.components, cfg.covariance == "full")
        self.x_norm, self.theta_norm = Standardizer(x_dim), Standardizer(theta_dim)
        self.net = nn.ModuleDict({"body": self.body, "head": self.head, "x_norm": self.x_norm, "theta_norm": self.theta_norm,
                                  **({} if self.projection is None else {"projection": self.projection})})

    def _nll(self, theta_std: torch.Tensor, x_std: torch.Tensor) -> torch.Tensor:
        return mixture_nll(*self.head(self.body(x_std)), theta_std)

    @torch.no_grad()
    def conditional(self, x_obs: torch.Tensor) -> GaussianMixture:
        """q(theta | x_obs) in parameter units, for one summary x_obs [F]."""
        self.net.eval()
        logits, means, U = self.head(self.body(self._inputs(x_obs.float().reshape(1, -1))))
        eye = torch.eye(self.theta_dim, dtype=torch.float64)
        U_inv = torch.linalg.solve_triangular(U[0].double(), eye.expand_as(U[0]), upper=True)
        covs = U_inv @ U_inv.transpose(-1, -2)
        std = GaussianMixture(logits[0], means[0], covs)
        return std.affine(self.theta_norm.shift, self.theta_norm.scale)


@register("model", "mdnn", MdnnConfig)
def mdnn(cfg: MdnnConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None) -> MDNN:
    return MDNN(cfg, theta_dim, x_dim, embedding)

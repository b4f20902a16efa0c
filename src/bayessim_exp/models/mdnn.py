"""MDNN: a mixture density network q(theta | x) with full- or diagonal-covariance components.

Inputs and targets are standardised with statistics of the first training set; components
are parameterised by the upper Cholesky factor U of their precision (positive diagonal via
exp), so that log N(theta; mu, (U^T U)^-1) = sum log diag U - |U (theta - mu)|^2 / 2 - D/2 log 2pi.

`ensemble` > 1: that many networks from different initialisations, each trained on its own
negative log-likelihood (in one loop, on the same batches), and q is their equally weighted
average, itself a Gaussian mixture (docs/statistics.md: averaging corrects overconfidence).
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
    ensemble: int  # networks averaged

    def validate(self) -> None:
        super().validate()
        if self.ensemble < 1:
            raise ConfigError(f"ensemble must be an integer >= 1, got {self.ensemble}")
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
            in_width = self.embedding(torch.zeros(2, x_dim if self.projection is None else theta_dim)).shape[-1]
        self.members = nn.ModuleList()
        for _ in range(cfg.ensemble):
            layers, width = [], in_width
            for h in cfg.hidden:
                layers += [nn.Linear(width, h), act()]
                width = h
            head = MixtureHead(width, theta_dim, cfg.components, cfg.covariance == "full")
            self.members.append(nn.Sequential(*layers, head))
        self.x_norm, self.theta_norm = Standardizer(x_dim), Standardizer(theta_dim)
        self.net = nn.ModuleDict({"embedding": self.embedding, "members": self.members, "x_norm": self.x_norm,
                                  "theta_norm": self.theta_norm,
                                  **({} if self.projection is None else {"projection": self.projection})})

    def _nll(self, theta_std: torch.Tensor, x_std: torch.Tensor) -> torch.Tensor:
        # the mean of the members' own losses: each member has its own gradients (early stopping is shared)
        h = self.embedding(x_std)
        return torch.stack([mixture_nll(*member(h), theta_std) for member in self.members]).mean(0)

    @torch.no_grad()
    def conditional(self, x_obs: torch.Tensor) -> GaussianMixture:
        """q(theta | x_obs) in parameter units, for one summary x_obs [F]: the members' mixtures, equally weighted."""
        self.net.eval()
        h = self.embedding(self._inputs(x_obs.float().reshape(1, -1)))
        logits, means, U = (torch.cat(parts) for parts in zip(*[
            (torch.log_softmax(lg[0].double(), -1), mu[0], u[0]) for lg, mu, u in (member(h) for member in self.members)]))
        eye = torch.eye(self.theta_dim, dtype=torch.float64)
        U_inv = torch.linalg.solve_triangular(U.double(), eye.expand_as(U), upper=True)
        covs = U_inv @ U_inv.transpose(-1, -2)
        std = GaussianMixture(logits, means, covs)
        return std.affine(self.theta_norm.shift, self.theta_norm.scale)


@register("model", "mdnn", MdnnConfig)
def mdnn(cfg: MdnnConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None) -> MDNN:
    return MDNN(cfg, theta_dim, x_dim, embedding)

"""A conditional neural spline flow q(theta | x) (zuko's NSF), a stronger model than the mixtures.

Its density has no closed-form product with Gaussians, so the SNPE-A correction cannot be done
analytically. Rounds after the first therefore use truncated proposals (TSNPE, Deistler et al.
2022): simulations come from the prior restricted to the previous posterior's highest-density
region (distributions/truncated_prior.py, `TruncatedPrior`), where the ratio prior / proposal is constant, so
q itself is the posterior on that region and needs no correction, only the restriction to the
prior's support. Given any other proposal, conditioning falls back to exact importance weights.
"""

from __future__ import annotations

import dataclasses
import math

import torch
import zuko
from torch import nn

from ..data_files import data_class
from ..distributions.base import ParameterDistribution, seeded_by
from ..errors import ConfigError
from .base import StandardizedDensityModel, Standardizer, TrainConfig
from .mdnn import input_projection


@data_class
@dataclasses.dataclass
class FlowConfig(TrainConfig):
    transforms: int  # autoregressive spline layers
    hidden: list[int]
    bins: int  # spline bins per transform

    def validate(self) -> None:
        super().validate()
        if self.calibrate:
            raise ConfigError("calibrate rescales Gaussian mixture components (mdnn, mdrff); a flow has none: "
                              "set model.calibrate=false")
        if self.transforms < 1 or self.bins < 2:
            raise ConfigError(f"transforms must be >= 1 and bins >= 2, got {self.transforms}, {self.bins}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must be a non-empty list of positive layer sizes, got {self.hidden}")


def _chunks(n: int, size: int) -> list[int]:
    return [min(size, n - start) for start in range(0, n, size)]


def _nsf(cfg: FlowConfig, theta_dim: int, context: int) -> zuko.flows.NSF:
    return zuko.flows.NSF(theta_dim, context, bins=cfg.bins, transforms=cfg.transforms, hidden_features=list(cfg.hidden))


@data_class
class FlowConditional(ParameterDistribution):
    """q(theta | x_obs) in parameter units: the flow on standardised theta, given its context (the embedded
    x_obs), mapped back. Saved as the flow's config, weights and context (data_files.py): the conditioned zuko
    distribution is rebuilt from them, and the embedding that made the context is not needed."""

    def __init__(self, cfg: FlowConfig, flow: zuko.flows.NSF, context: torch.Tensor, shift: torch.Tensor,
                 scale: torch.Tensor):
        self.cfg, self.flow, self.context = cfg, flow, context
        self.dist = flow(context)
        self.shift, self.scale = shift.double(), scale.double()
        self._log_jacobian = torch.log(self.scale).sum()

    def to_state(self) -> dict:
        return {"cfg": self.cfg, "flow": self.flow.state_dict(), "context": self.context, "shift": self.shift,
                "scale": self.scale}

    @classmethod
    @torch.no_grad()
    def from_state(cls, fields: dict) -> FlowConditional:
        flow = _nsf(fields["cfg"], fields["shift"].shape[0], fields["context"].shape[-1])
        flow.load_state_dict(fields["flow"])
        return cls(fields["cfg"], flow.eval(), fields["context"], fields["shift"], fields["scale"])

    @property
    def dim(self) -> int:
        return self.shift.shape[0]

    @torch.no_grad()
    def sample(self, shape: tuple[int, ...] = (1,), generator: torch.Generator | None = None) -> torch.Tensor:
        n = math.prod(shape)
        # the autoregressive inverse runs the network once per dimension: bound its memory by chunks
        with seeded_by(generator):
            z = torch.cat([self.dist.sample((k,)) for k in _chunks(n, 4096)]).double()
        return (self.shift + self.scale * z).reshape(*shape, self.dim)

    @torch.no_grad()
    def log_prob(self, theta: torch.Tensor) -> torch.Tensor:
        z = (theta.double() - self.shift) / self.scale
        flat = z.reshape(-1, self.dim).float()
        lp = torch.cat([self.dist.log_prob(chunk) for chunk in flat.split(65536)]).double()
        return lp.reshape(z.shape[:-1]) - self._log_jacobian


@data_class
class Flow(StandardizedDensityModel):
    """`embedding` (optional, as for MDNN): a trainable module mapping standardised summaries
    [N, x_dim] to the flow's context [N, E], trained jointly."""

    def __init__(self, cfg: FlowConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None):
        self.cfg, self.theta_dim, self.x_dim = cfg, theta_dim, x_dim
        self.embedding = embedding if embedding is not None else nn.Identity()
        self.projection = input_projection(cfg, theta_dim, x_dim, embedding)
        with torch.no_grad():
            context = self.embedding(torch.zeros(2, x_dim if self.projection is None else theta_dim)).shape[-1]
        self.flow = _nsf(cfg, theta_dim, context)
        self.x_norm, self.theta_norm = Standardizer(x_dim), Standardizer(theta_dim)
        self.net = nn.ModuleDict({"embedding": self.embedding, "flow": self.flow,
                                  "x_norm": self.x_norm, "theta_norm": self.theta_norm,
                                  **({} if self.projection is None else {"projection": self.projection})})

    def _nll(self, theta_std: torch.Tensor, x_std: torch.Tensor) -> torch.Tensor:
        return -self.flow(self.embedding(x_std)).log_prob(theta_std)

    @torch.no_grad()
    def conditional(self, x_obs: torch.Tensor) -> FlowConditional:
        """q(theta | x_obs) for one summary x_obs [F], with sample and log_prob in parameter units."""
        self.net.eval()
        context = self.embedding(self.inputs(x_obs.float().reshape(1, -1)))[0]
        return FlowConditional(self.cfg, self.flow, context, self.theta_norm.shift, self.theta_norm.scale)


def flow(cfg: FlowConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None) -> Flow:
    return Flow(cfg, theta_dim, x_dim, embedding)

"""MDNN: a mixture density network q(theta | x) with full- or diagonal-covariance components.

Inputs and targets are standardised with statistics of the first training set; components
are parameterised by the upper Cholesky factor U of their precision (positive diagonal via
exp), so that log N(theta; mu, (U^T U)^-1) = sum log diag U - |U (theta - mu)|^2 / 2 - D/2 log 2pi.

`ensemble` > 1: that many networks from different initialisations, each trained on its own
negative log-likelihood (in one loop, on the same batches), and q is their equally weighted
average, itself a Gaussian mixture (docs/statistics.md: averaging corrects overconfidence).

`calibrate`: after training, one factor per parameter on the standard deviations of every
component (in standardised units), fitted by maximum likelihood on the validation split. A network
stopped early is over- or under-dispersed, by different amounts per parameter; rescaling is
temperature scaling (Guo et al. 2017) per output, and it can only raise the validation likelihood.
Then one common factor that calibrates the joint HPD regions on the same pairs (models/spread.py).

`set_support(low, high)`: the posterior is read truncated to that box (a box-space model, whose posteriors the
conditioning truncates to the prior's box): the network is then trained, and its spread calibrated, on the
truncated mixture's likelihood and regions (models/box_mass.py), for diagonal components or D <= 2.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Literal

import numpy as np
import torch
from scipy import optimize
from torch import nn

from ..data_files import data_class
from ..distributions.mixture import GaussianMixture, MixtureBatch
from ..errors import ConfigError
from .base import StandardizedDensityModel, Standardizer, TrainConfig
from .box_mass import TruncatedMixtureBatch, log_box_mass, supported
from .mixture_nll import LOG_DIAGONAL_BOUND, HeadNLL, mixture_nll
from .projection import RidgeProjection
from .spread import JOINT_ROWS, SpreadScale, joint_factor, member_shares

_CALIBRATION_ROWS = 4096  # validation pairs the spread is fitted on (plenty for one factor per parameter)
_CALIBRATION_CHUNK = 512  # pairs per pass: dense precision factors of 100-parameter mixtures are large
ACTIVATIONS = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU, "silu": nn.SiLU}
Activation = Literal["relu", "tanh", "elu", "silu"]  # ACTIVATIONS' keys
Covariance = Literal["full", "diagonal"]


@data_class
@dataclasses.dataclass
class MdnnConfig(TrainConfig):
    components: int
    hidden: list[int]
    activation: Activation
    covariance: Covariance
    ensemble: int  # networks averaged

    def validate(self) -> None:
        super().validate()
        if self.ensemble < 1:
            raise ConfigError(f"ensemble must be an integer >= 1, got {self.ensemble}")
        if self.components < 1:
            raise ConfigError(f"components must be an integer >= 1, got {self.components}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must be a non-empty list of positive layer sizes, got {self.hidden}")


def input_projection(cfg: TrainConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None) -> RidgeProjection | None:
    if not cfg.project_inputs:
        return None
    if embedding is not None:
        raise ConfigError("project_inputs replaces the summaries by linear predictions; it cannot follow a learned "
                          "embedding (summarizer=learned): set model.project_inputs=false")
    return RidgeProjection(x_dim, theta_dim)


class MixtureHead(nn.Module):
    """Where a mixture sits in a network's outputs [N, K (1 + 2 D + P)]: logits [K], means [K, D], precision
    factors U [K, D, D] (log-diagonals, then the strict upper triangle row by row: P = D (D - 1) / 2 for full
    factors, 0 for diagonal ones). No parameters: the last layer of `MemberNetworks` writes the outputs."""

    def __init__(self, dim: int, components: int, full: bool):
        super().__init__()
        self.dim, self.k, self.full = dim, components, full
        self.n_off = dim * (dim - 1) // 2 if full else 0
        self.width = components * (1 + 2 * dim + self.n_off)
        # where U's entries land in its flattened rows: the diagonal, then the strict upper triangle
        upper = torch.triu_indices(dim, dim, offset=1) if full else torch.zeros(2, 0, dtype=torch.long)
        self.register_buffer("positions", torch.cat([torch.arange(dim) * (dim + 1), upper[0] * dim + upper[1]]),
                             persistent=False)
        self.register_buffer("upper_rows", upper[0].contiguous(), persistent=False)
        self.register_buffer("upper_cols", upper[1].contiguous(), persistent=False)

    def forward(self, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        k, d = self.k, self.dim
        logits, means, log_diag, off = torch.split(out, [k, k * d, k * d, k * self.n_off], -1)
        # U by one scatter into zeros (conditioning and the checks; training reads `out` directly, `nll`)
        diagonal = torch.exp(log_diag.reshape(-1, k, d).clamp(-LOG_DIAGONAL_BOUND, LOG_DIAGONAL_BOUND))
        entries = torch.cat([diagonal, off.reshape(len(out), k, self.n_off)], -1)
        U = out.new_zeros(len(out), k, d * d).index_copy(-1, self.positions, entries).reshape(-1, k, d, d)
        return logits, means.reshape(-1, k, d), U

    def nll(self, out: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
        """-log q(theta_n | out_n) [N], straight from the outputs (training: few kernels, models/mixture_nll.py)."""
        return HeadNLL.apply(out, theta, self.upper_rows, self.upper_cols, self.k)


class MemberNetworks(nn.Module):
    """`count` networks of one shape side by side (an ensemble's members): features [N, in] -> outputs
    [count, N, out], each layer one batched product for every member. On a 16-core CPU an ensemble of three
    trained 1.8 times as fast as three networks one after the other (docs/benchmarks.md). Each member is
    initialised as nn.Linear layers would be, member after member, layer after layer (the draws of a
    ModuleList of nn.Sequential members, whose states `MDNN.load_state_dict` still reads)."""

    def __init__(self, count: int, in_width: int, hidden: list[int], activation: type[nn.Module], out_width: int):
        super().__init__()
        self.count = count
        widths = [in_width, *hidden, out_width]
        self.weights = nn.ParameterList([nn.Parameter(torch.empty(count, a, b)) for a, b in zip(widths, widths[1:])])
        self.biases = nn.ParameterList([nn.Parameter(torch.empty(count, 1, b)) for b in widths[1:]])
        self.activation = activation()
        self.reset_parameters()

    def reset_parameters(self) -> None:
        with torch.no_grad():
            for m in range(self.count):
                for weight, bias in zip(self.weights, self.biases):
                    layer = nn.Linear(weight.shape[1], weight.shape[2])  # its reset: nn.Linear's draws
                    weight[m].copy_(layer.weight.T)
                    bias[m, 0].copy_(layer.bias)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        out = h.expand(self.count, *h.shape)
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases)):
            out = torch.baddbmm(bias, out, weight)
            if i < len(self.weights) - 1:
                out = self.activation(out)
        return out


@data_class
class MDNN(StandardizedDensityModel):
    """`embedding` (optional): a trainable module in front of the network, trained jointly
    (learned summaries); it maps standardised summaries [N, x_dim] to features [N, E]."""

    support: tuple[torch.Tensor, torch.Tensor] | None = None  # parameter units: set_support
    _device_support: tuple | None = None  # (device, low, high): _support_on

    def __init__(self, cfg: MdnnConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None):
        self.cfg, self.theta_dim, self.x_dim = cfg, theta_dim, x_dim
        act = ACTIVATIONS[cfg.activation]
        self.embedding = embedding if embedding is not None else nn.Identity()
        self.projection = input_projection(cfg, theta_dim, x_dim, embedding)
        with torch.no_grad():
            in_width = self.embedding(torch.zeros(2, x_dim if self.projection is None else theta_dim)).shape[-1]
        self.head = MixtureHead(theta_dim, cfg.components, cfg.covariance == "full")
        self.members = MemberNetworks(cfg.ensemble, in_width, cfg.hidden, act, self.head.width)
        self.x_norm, self.theta_norm, self.spread = Standardizer(x_dim), Standardizer(theta_dim), SpreadScale(theta_dim)
        self.net = nn.ModuleDict({"embedding": self.embedding, "members": self.members, "head": self.head,
                                  "x_norm": self.x_norm, "theta_norm": self.theta_norm, "spread": self.spread,
                                  **({} if self.projection is None else {"projection": self.projection})})

    def set_support(self, low: torch.Tensor | None, high: torch.Tensor | None = None) -> bool:
        """Train and calibrate the mixture truncated to the box [low, high] (parameter units; None: untruncated)
        from the next fit on; False (and untruncated) where the box mass is not computed for these components."""
        trains_here = type(self)._nll is MDNN._nll  # a subclass with its own loss (mdrff) stays untruncated
        if low is None or not trains_here or not supported(self.theta_dim, self.cfg.covariance == "diagonal"):
            self.support = None
            return low is None
        self.support = (torch.as_tensor(low, dtype=torch.float64), torch.as_tensor(high, dtype=torch.float64))
        self._device_support = None
        return True

    def _support_on(self, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
        """The support copied to `device` once: a copy from the CPU inside the loss would keep a CUDA graph from
        capturing the training step (models/adam_steps.py)."""
        if self._device_support is None or self._device_support[0] != device:
            self._device_support = (device, *(bound.to(device) for bound in self.support))
        return self._device_support[1], self._device_support[2]

    def _standardised_support(self, device: torch.device) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The support in standardised units (float64 [D] each), None where untruncated."""
        if self.support is None:
            return None
        low, high = self._support_on(device)
        shift, scale = self.theta_norm.shift.double(), self.theta_norm.scale.double()
        return (low - shift) / scale, (high - shift) / scale

    def _log_box_mass(self, log_w: torch.Tensor, means: torch.Tensor, U: torch.Tensor) -> torch.Tensor:
        """log of the mixture's mass inside the support [N] (standardised units)."""
        log_mass = log_box_mass(means, U, *self._standardised_support(means.device),
                                diagonal=self.cfg.covariance == "diagonal")
        return torch.logsumexp(log_w + log_mass, -1)

    def _nll(self, theta_std: torch.Tensor, x_std: torch.Tensor) -> torch.Tensor:
        # the mean of the members' own losses: each member has its own gradients (early stopping is shared)
        out = self.members(self.embedding(x_std))
        count = len(out)
        flat = out.reshape(-1, out.shape[-1])
        losses = self.head.nll(flat, theta_std.repeat(count, 1))
        if self.support is not None:  # the truncated mixture: minus log of its mass inside the box
            logits, means, U = self.head(flat)
            losses = losses + self._log_box_mass(torch.log_softmax(logits, -1), means, U)
        return losses if count == 1 else losses.reshape(count, -1).mean(0)

    def _mixtures(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The members' mixtures side by side, equally weighted: log weights [N, M], means [N, M, D],
        precision factors [N, M, D, D] (M: every member's components, member after member; standardised
        units, before the spread calibration)."""
        out = self.members(self.embedding(inputs))
        count, n = out.shape[:2]
        logits, means, U = self.head(out.reshape(count * n, -1))

        def side_by_side(part: torch.Tensor) -> torch.Tensor:  # [count N, K, ...] -> [N, count K, ...]
            part = part.reshape(count, n, *part.shape[1:]).transpose(0, 1)
            return part.reshape(n, -1, *part.shape[3:])

        log_w = side_by_side(torch.log_softmax(logits, -1)) - math.log(count)
        return log_w, side_by_side(means), side_by_side(U)

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict({**state, "net": _stacked_members(state["net"])})

    def _calibrate(self, theta_std: torch.Tensor, inputs: torch.Tensor, seed: int) -> dict:
        self.net.eval()
        rows = torch.arange(min(len(theta_std), _CALIBRATION_ROWS), device=theta_std.device).split(_CALIBRATION_CHUNK)
        with torch.no_grad():  # the network is fixed: its outputs once, the factors by L-BFGS on them
            outputs = [(theta_std[r], *self._mixtures(inputs[r])) for r in rows]
        count = sum(len(t) for t, *_ in outputs)

        def nll_and_grad(values: np.ndarray) -> tuple[float, np.ndarray]:
            log_scale = torch.tensor(values, dtype=torch.float32, device=theta_std.device, requires_grad=True)
            total = 0.0
            for theta, log_w, means, U in outputs:
                scaled = self.spread.scale_factors(U, log_scale)
                loss = mixture_nll(log_w, means, scaled, theta)
                if self.support is not None:
                    loss = loss + self._log_box_mass(log_w, means, scaled)
                loss = loss.sum() / count
                loss.backward()
                total += loss.item()
            return total, log_scale.grad.double().cpu().numpy()

        # scipy's L-BFGS rather than torch.optim's, whose import pulls in torch._dynamo (models/adam.py)
        found = optimize.minimize(nll_and_grad, np.zeros(self.theta_dim), jac=True, method="L-BFGS-B",
                                  options={"maxiter": 100})
        log_scale = torch.as_tensor(found.x, dtype=torch.float32)
        if torch.isfinite(log_scale).all():  # else keep the network's own spread
            self.spread.log_scale.copy_(log_scale)
        with torch.no_grad():
            # the first JOINT_ROWS pairs, from the chunks that hold them (dense factors of all 4,096 are gigabytes)
            first = outputs[:math.ceil(JOINT_ROWS / _CALIBRATION_CHUNK)]
            theta, log_w, means, U = (torch.cat(part)[:JOINT_ROWS] for part in zip(*first))
            diagonal, box = self.cfg.covariance == "diagonal", self._standardised_support(theta.device)
            joint, record = joint_factor(log_w, means, self.spread.scale_factors(U), theta, diagonal=diagonal,
                                         seed=seed, box=box)
            self.spread.log_scale.add_(math.log(joint))
            if self.members.count > 1:
                record["members_inside"] = member_shares(log_w, means, self.spread.scale_factors(U), theta,
                                                         self.members.count, diagonal=diagonal, seed=seed, box=box)
        return {"spread_scale": torch.exp(self.spread.log_scale).tolist(),
                "joint_spread": {"factor": joint, **record}}

    @torch.no_grad()
    def conditionals(self, x: torch.Tensor) -> MixtureBatch:
        """q(theta | x_n) in parameter units for every row of x [N, F] (held-out checks, batched)."""
        self.net.eval()
        log_w, means, U = self._mixtures(self.inputs(x.float()))
        shift, scale = self.theta_norm.shift.double(), self.theta_norm.scale.double()
        # theta = shift + scale * theta_std: the precision factors divide by the scale, column by column
        means, factors = means.double() * scale + shift, self.spread.scale_factors(U).double() / scale
        if self.support is not None:  # trained as the mixture truncated to the box: checked as it
            return TruncatedMixtureBatch(log_w, means, factors, *self.support, diagonal=self.cfg.covariance == "diagonal")
        return MixtureBatch(log_w, means, factors)

    @torch.no_grad()
    def conditional(self, x_obs: torch.Tensor) -> GaussianMixture:
        """q(theta | x_obs) in parameter units, for one summary x_obs [F]: the members' mixtures, equally weighted."""
        self.net.eval()
        log_w, means, U = (part[0] for part in self._mixtures(self.inputs(x_obs.float().reshape(1, -1))))
        logits, U = log_w.double(), self.spread.scale_factors(U)
        eye = torch.eye(self.theta_dim, dtype=torch.float64)
        U_inv = torch.linalg.solve_triangular(U.double(), eye.expand_as(U), upper=True)
        covs = U_inv @ U_inv.transpose(-1, -2)
        std = GaussianMixture(logits, means, covs)
        return std.affine(self.theta_norm.shift, self.theta_norm.scale)


def _stacked_members(net: dict) -> dict:
    """A network state with the members' layers stacked (MemberNetworks), from one saved with a ModuleList of
    nn.Sequential members (members.<m>.<i>.weight; the head's layer: members.<m>.<i>.out.weight)."""
    old = [k for k in net if re.fullmatch(r"members\.\d+\.\d+\.(out\.)?(weight|bias)", k)]
    if not old:
        return net
    layers: dict[int, dict[int, str]] = {}  # member -> Sequential index -> the layer's key prefix
    for key in old:
        _, member, index, *_ = key.split(".")
        layers.setdefault(int(member), {})[int(index)] = key.rsplit(".", 1)[0]
    members = [[prefixes[i] for i in sorted(prefixes)] for _, prefixes in sorted(layers.items())]
    stacked = {k: v for k, v in net.items() if k not in old}
    for i in range(len(members[0])):
        stacked[f"members.weights.{i}"] = torch.stack([net[f"{layer[i]}.weight"].T for layer in members])
        stacked[f"members.biases.{i}"] = torch.stack([net[f"{layer[i]}.bias"][None] for layer in members])
    return stacked


def mdnn(cfg: MdnnConfig, theta_dim: int, x_dim: int, embedding: nn.Module | None = None) -> MDNN:
    return MDNN(cfg, theta_dim, x_dim, embedding)

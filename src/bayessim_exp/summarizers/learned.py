"""`learned`: a trainable embedding over the trajectory, trained jointly with the posterior model.

The summarizer itself returns fixed features: the trajectory at `time_points` evenly spaced
times, each time as [state, action in force, alive flag], flattened time-major to [N, K*C]. Its
`embedding` (an nn.Module, [N, K*C] -> [N, embedding_dim]) is handed to the model factory by the
pipeline, and the model trains it by backpropagation together with its own weights.

The embedding's first layer is lazy (its input width depends on the task's state and action
sizes); `output_dim`, which tells the summarizer those sizes and which the pipeline calls before
building the model, fixes it with a dry run so that optimizers see materialised parameters.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import torch
from torch import nn

from ..errors import ConfigError
from ..sim.trajectories import Trajectories
from .basic import evenly_spaced_times
from .masking import held_actions, held_states, valid_steps


@dataclasses.dataclass
class LearnedConfig:
    time_points: int  # K times the trajectory is sampled at
    architecture: Literal["conv", "mlp"]  # conv: 1D convolutions over the K times, mean-pooled; mlp: on the flat features
    hidden: list[int]  # conv channels or MLP widths
    kernel_size: int  # conv only, in time points
    embedding_dim: int  # E

    def validate(self) -> None:
        if self.time_points < 2:
            raise ConfigError(f"time_points must be >= 2, got {self.time_points}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must be a non-empty list of positive sizes, got {self.hidden}")
        if self.kernel_size < 1:
            raise ConfigError(f"kernel_size must be >= 1, got {self.kernel_size}")
        if self.embedding_dim < 1:
            raise ConfigError(f"embedding_dim must be >= 1, got {self.embedding_dim}")


class TimeConvEmbedding(nn.Module):
    """[N, K*C] time-major -> [N, E]: Conv1d layers over the K times, mean over time, linear."""

    def __init__(self, time_points: int, channels: list[int], kernel_size: int, embedding_dim: int):
        super().__init__()
        self.time_points = time_points
        layers: list[nn.Module] = [nn.LazyConv1d(channels[0], kernel_size, padding=kernel_size // 2), nn.ReLU()]
        for c_in, c_out in zip(channels, channels[1:]):
            layers += [nn.Conv1d(c_in, c_out, kernel_size, padding=kernel_size // 2), nn.ReLU()]
        self.conv = nn.Sequential(*layers)
        self.out = nn.Linear(channels[-1], embedding_dim)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        x = features.reshape(features.shape[0], self.time_points, -1).transpose(1, 2)
        return self.out(self.conv(x).mean(-1))


def mlp_embedding(widths: list[int], embedding_dim: int) -> nn.Sequential:
    layers: list[nn.Module] = [nn.LazyLinear(widths[0]), nn.ReLU()]
    for w_in, w_out in zip(widths, widths[1:]):
        layers += [nn.Linear(w_in, w_out), nn.ReLU()]
    return nn.Sequential(*layers, nn.Linear(widths[-1], embedding_dim))


class LearnedSummarizer:
    def __init__(self, cfg: LearnedConfig):
        self.cfg = cfg
        self.embedding_dim = cfg.embedding_dim
        if cfg.architecture == "conv":
            self.embedding: nn.Module = TimeConvEmbedding(cfg.time_points, cfg.hidden, cfg.kernel_size, cfg.embedding_dim)
        else:
            self.embedding = mlp_embedding(cfg.hidden, cfg.embedding_dim)

    def check(self, horizon: int) -> None:
        if self.cfg.time_points > horizon + 1:
            raise ConfigError(
                f"summarizer time_points={self.cfg.time_points} exceeds the {horizon + 1} states of the horizon {horizon}"
            )

    def output_dim(self, state_dim: int, action_dim: int, horizon: int) -> int:
        dim = self.cfg.time_points * (state_dim + action_dim + 1)
        with torch.no_grad():
            self.embedding(torch.zeros(1, dim))  # materialises the lazy first layer
        return dim

    def __call__(self, traj: Trajectories) -> torch.Tensor:
        self.check(traj.horizon)
        idx = evenly_spaced_times(traj.horizon, self.cfg.time_points).to(traj.states.device)
        points = traj.horizon + 1
        alive = (torch.arange(points, device=idx.device) <= valid_steps(traj)[:, None]).to(traj.states.dtype)
        per_time = torch.cat([held_states(traj), held_actions(traj, points), alive[..., None]], -1)
        return per_time[:, idx].flatten(1)


def learned(cfg: LearnedConfig) -> LearnedSummarizer:
    return LearnedSummarizer(cfg)

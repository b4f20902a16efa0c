"""`signatory`: the truncated (log-)signature of the path [time, states, actions].

The name matches BayesSimIG's option; the computation runs through pysiglib's torch API
(autograd on CPU and, where pysiglib was built with CUDA, GPU) or, with `backend: torch`, through
the plain-torch tensor algebra in `tensor_algebra` on any device.

Path point p = 0..T is (time, s[p], a[p]) with the final state keeping the last action. After
an episode ends every channel, time included, holds its last valid value: the path stops, so the
invalid steps add nothing to the signature, while the time channel's total increment still says
when the episode ended. Time runs over [0, 1] for a full episode.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import pysiglib
import pysiglib.torch_api as siglib
import torch

from ..errors import ConfigError
from ..sim.trajectories import Trajectories
from . import tensor_algebra
from .masking import held_actions, held_states, valid_steps


@dataclasses.dataclass
class SignatureConfig:
    depth: int  # truncation level; the size grows as channels ** depth
    log_signature: bool  # coefficients of the log-signature on the Lyndon words instead
    time_augment: bool  # prepend the time channel; without it the signature ignores speed
    lead_lag: bool  # (lag, lead) copies of the state-action channels: adds quadratic variation
    basepoint: bool  # start the path at the origin, so the signature sees the initial state
    backend: Literal["pysiglib", "torch"]
    threads: int  # pysiglib CPU threads (-1: all)
    max_features: int  # refuse, before simulating, summaries larger than this

    def validate(self) -> None:
        if self.depth < 1:
            raise ConfigError(f"depth must be >= 1, got {self.depth}")
        if self.threads == 0:
            raise ConfigError("threads must be >= 1, or negative to count back from all threads")


def signature_path(traj: Trajectories, time_augment: bool, lead_lag: bool, basepoint: bool) -> torch.Tensor:
    """[N, L, d] the path whose signature is taken; see the module docstring."""
    points = traj.horizon + 1
    channels = torch.cat([held_states(traj), held_actions(traj, points)], -1)
    steps = torch.arange(points, device=channels.device).minimum(valid_steps(traj)[:, None])
    time = (steps.to(channels.dtype) / traj.horizon)[..., None]
    if lead_lag:
        # points x0,x0,x1,x1,... (lag) beside x0,x1,x1,x2,... (lead), pysiglib's (lag, lead) order
        doubled = channels.repeat_interleave(2, 1)
        channels = torch.cat([doubled[:, :-1], doubled[:, 1:]], -1)
        doubled_time = time.repeat_interleave(2, 1)
        time = (doubled_time[:, :-1] + doubled_time[:, 1:]) / 2
    path = torch.cat([time, channels], -1) if time_augment else channels
    if basepoint:
        path = torch.cat([torch.zeros_like(path[:, :1]), path], 1)
    return path


def pysiglib_signature(path: torch.Tensor, depth: int, log_signature: bool, threads: int = 1) -> torch.Tensor:
    """pysiglib's signature (no scalar term) or log-signature in the Lyndon "words" basis (method 1)."""
    if path.is_cuda and not pysiglib.BUILT_WITH_CUDA:
        raise ConfigError("this pysiglib was built without CUDA: use summarizer.backend=torch on the GPU")
    if not log_signature:
        return siglib.sig(path, depth, n_jobs=threads)
    pysiglib.prepare_log_sig(path.shape[-1], depth, method=1, device="cuda" if path.is_cuda else "cpu")
    return siglib.log_sig(path, depth, method=1, n_jobs=threads)


class SignatureSummarizer:
    def __init__(self, cfg: SignatureConfig):
        self.cfg = cfg

    def check(self, horizon: int) -> None:
        if horizon < 1:
            raise ConfigError(f"the signature needs at least one step, the horizon is {horizon}")

    def path_dim(self, state_dim: int, action_dim: int) -> int:
        return (2 if self.cfg.lead_lag else 1) * (state_dim + action_dim) + (1 if self.cfg.time_augment else 0)

    def output_dim(self, state_dim: int, action_dim: int, horizon: int) -> int:
        dim = self.path_dim(state_dim, action_dim)
        length = (tensor_algebra.log_signature_length if self.cfg.log_signature else tensor_algebra.signature_length)
        size = length(dim, self.cfg.depth)
        if size > self.cfg.max_features:
            raise ConfigError(
                f"the depth-{self.cfg.depth} {'log-' if self.cfg.log_signature else ''}signature of this task's "
                f"{dim}-channel path has {size} features (max_features={self.cfg.max_features}); lower "
                "summarizer.depth, set summarizer.log_signature=true, or raise summarizer.max_features"
            )
        return size

    def __call__(self, traj: Trajectories) -> torch.Tensor:
        self.check(traj.horizon)
        cfg = self.cfg
        path = signature_path(traj, cfg.time_augment, cfg.lead_lag, cfg.basepoint)
        if cfg.backend == "torch":
            return tensor_algebra.signature_features(path, cfg.depth, cfg.log_signature)
        return pysiglib_signature(path.contiguous(), cfg.depth, cfg.log_signature, cfg.threads)


def signatory(cfg: SignatureConfig) -> SignatureSummarizer:
    return SignatureSummarizer(cfg)

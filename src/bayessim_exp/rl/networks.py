"""PPO's networks: a Gaussian actor and a critic sharing one running observation normaliser.

The normaliser lives inside the networks (not in the environment) so a saved actor is self-contained:
collect policies, evaluation on the surrogate real system and a later round's fine-tuning all feed it
raw observations.
"""

from __future__ import annotations

import torch
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from torch import nn
from torchrl.modules import MLP, IndependentNormal, ProbabilisticActor, ValueOperator


class RunningNorm(nn.Module):
    """(x - mean) / std over every observation seen by `update`, clipped to +-clip."""

    def __init__(self, dim: int, clip: float):
        super().__init__()
        self.clip = clip
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.tensor(1e-4))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        x = x.reshape(-1, x.shape[-1]).to(self.mean)
        n, mean, var = x.shape[0], x.mean(0), x.var(0, unbiased=False)
        total = self.count + n
        delta = mean - self.mean
        # Chan et al.'s parallel update of mean and variance
        self.var.copy_((self.var * self.count + var * n + delta**2 * self.count * n / total) / total)
        self.mean.add_(delta * n / total)
        self.count.copy_(total)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return ((x - self.mean) / (self.var + 1e-8).sqrt()).clamp(-self.clip, self.clip)


class Agent(nn.Module):
    """actor: observation -> loc, scale, action, sample_log_prob; critic: observation -> state_value."""

    def __init__(self, obs_dim: int, action_dim: int, hidden: list[int], obs_clip: float, init_log_std: float):
        super().__init__()
        self.norm = RunningNorm(obs_dim, obs_clip)
        policy_net = nn.Sequential(
            self.norm, MLP(in_features=obs_dim, out_features=action_dim, num_cells=hidden, activation_class=nn.Tanh),
            AddStateIndependentNormalScale(action_dim, init_value=init_log_std, scale_lb=1e-3))
        self.actor = ProbabilisticActor(
            TensorDictModule(policy_net, in_keys=["observation"], out_keys=["loc", "scale"]),
            in_keys=["loc", "scale"], distribution_class=IndependentNormal, return_log_prob=True)
        value_net = nn.Sequential(
            self.norm, MLP(in_features=obs_dim, out_features=1, num_cells=hidden, activation_class=nn.Tanh))
        self.critic = ValueOperator(value_net, in_keys=["observation"])

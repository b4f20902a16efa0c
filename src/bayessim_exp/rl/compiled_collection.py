"""PPO's collection compiled with the simulator: on MJX the actor runs inside the compiled rollout.

torchrl's Collector steps the environment from Python, one jitted simulator call and one actor call per
control step; on a GPU that costs more than the physics. Here a batch of num_envs x rollout_steps steps is
one call of `MjxSimulator.closed_loop`: a JAX copy of the actor's mean network (observation normaliser,
tanh MLP), handed the current weights before every batch, samples the Gaussian actions from noise drawn in
torch, each slot resets inside the loop with the environment's draws (rl/env.py's ResetDraws), and the
batch comes back to torch by DLPack in the layout of torchrl's Collector ([N, T]; observation, action,
action_log_prob and the "next" entries GAE and the loss read). torchrl stays the PPO: loss, GAE, optimiser.

Same seed, same trajectories as the Collector over SimulatorEnv with a policy fed the same noise
(tests/unit/test_compiled_collection.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

import torch
from tensordict import TensorDict
from torch import nn

from .env import SimulatorEnv
from .networks import Agent

NoiseSource = Callable[[tuple[int, ...], torch.device], torch.Tensor]


def standard_normal(shape: tuple[int, ...], device: torch.device) -> torch.Tensor:
    return torch.randn(shape, device=device)  # torch's generator: the run's seed decides it


def can_compile(env: SimulatorEnv) -> bool:
    """The environment's simulator runs closed loops (MJX with every reset on the device)."""
    return getattr(env.sim, "closes_loops", False)


def actor_arrays(agent: Agent, device: torch.device) -> tuple:
    """The actor's weights as JAX arrays on the simulator's `device` (copies: the optimiser updates the torch
    ones in place while a dispatched JAX loop may still read them): normaliser mean, std and clip, the MLP's
    (weight, bias) pairs in order, and the state-independent scale."""
    import jax.numpy as jnp

    def put(t: torch.Tensor):
        return jnp.from_dlpack(t.detach().to(device, torch.float32).contiguous().clone())

    policy_net = agent.actor.module[0].module  # ProbabilisticActor -> TensorDictModule -> norm, MLP, scale
    norm, mlp, _ = policy_net
    layers = [m for m in mlp if isinstance(m, nn.Linear)]
    if sum(isinstance(m, nn.Tanh) for m in mlp) != len(layers) - 1:
        raise TypeError("the compiled actor mirrors a tanh MLP (rl/networks.py's Agent)")
    with torch.no_grad():
        _, scale = policy_net(torch.zeros(1, norm.mean.shape[0], device=norm.mean.device))
    std = (norm.var + 1e-8).sqrt()
    return (put(norm.mean), put(std), norm.clip, [(put(m.weight), put(m.bias)) for m in layers], put(scale[0]))


def gaussian_actor(arrays: tuple, obs, noise):
    """The JAX twin of the actor: loc = MLP(normalised obs), action = loc + scale * noise, its log-density."""
    import jax
    import jax.numpy as jnp

    mean, std, clip, layers, scale = arrays
    x = jnp.clip((obs - mean) / std, -clip, clip)
    with jax.default_matmul_precision("float32"):  # torch's float32 products, not a GPU's TF32 default
        for i, (w, b) in enumerate(layers):
            x = x @ w.T + b
            x = jnp.tanh(x) if i < len(layers) - 1 else x
    log_prob = (-0.5 * noise**2 - jnp.log(scale) - 0.5 * math.log(2 * math.pi)).sum(-1)
    return x + scale * noise, {"action_log_prob": log_prob}


class CompiledCollector:
    """Iterates batches of env.num_envs x rollout_steps steps until `total` steps, as torchrl's Collector does."""

    def __init__(self, env: SimulatorEnv, agent: Agent, rollout_steps: int, total: int, seed: int,
                 noise: NoiseSource = standard_normal):
        if not can_compile(env):
            raise ValueError("the compiled collection needs a simulator that runs closed loops (sim=mjx)")
        self.env, self.agent, self.rollout_steps, self.total, self.noise = env, agent, rollout_steps, total, noise
        env.set_seed(seed)

    def __iter__(self) -> Iterator[TensorDict]:
        sim, steps = self.env.sim, self.rollout_steps
        self.env.reset()  # as the Collector's first reset: the draws of the step before the first
        self._episode_return = torch.zeros(sim.num_envs, device=sim.device)
        for _ in range(self.total // (sim.num_envs * steps)):
            params, states = self.env.draws.take(steps)
            noise = self.noise((steps, sim.num_envs, sim.task.action_dim), sim.device)
            out = sim.closed_loop(gaussian_actor, actor_arrays(self.agent, sim.device), noise, params, states)
            yield self._batch(out).to(self.agent.norm.mean.device)  # where the update runs

    def _batch(self, out: dict[str, Any]) -> TensorDict:
        """[T, N] arrays -> the Collector's [N, T] TensorDict, with RewardSum's running episode returns."""
        reward, terminated, truncated = out["reward"], out["terminated"], out["truncated"]
        done = terminated | truncated
        returns = torch.empty_like(reward)
        running = self._episode_return
        for t in range(reward.shape[0]):
            running = running + reward[t]
            returns[t] = running
            running = torch.where(done[t], 0.0, running)
        self._episode_return = running

        def nt(x: torch.Tensor, trailing: bool = False) -> torch.Tensor:
            x = x.transpose(0, 1)
            return x[..., None] if trailing else x

        n, t = reward.shape[1], reward.shape[0]
        return TensorDict({
            "observation": nt(out["observation"]), "action": nt(out["action"]),
            "action_log_prob": nt(out["action_log_prob"]),
            "next": {"observation": nt(out["next_observation"]), "reward": nt(reward, True),
                     "done": nt(done, True), "terminated": nt(terminated, True), "truncated": nt(truncated, True),
                     "episode_reward": nt(returns, True)},
        }, batch_size=[n, t], device=reward.device)

    def shutdown(self) -> None:
        """torchrl's Collector's interface: nothing to release."""

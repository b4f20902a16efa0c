"""PPO's compiled collection (rl/compiled_collection.py) against torchrl's Collector stepping SimulatorEnv
over the same MJX simulator: the same actor, seed and action noise give the same batches, resets with
new parameters inside the batch included; and PPO trains through it.

The stated tolerance: 1e-4 on observations, actions, rewards and log-densities (the same float32 physics
compiled as one loop or as single steps; the actor in JAX or torch); done flags and episode returns exactly
equal or to the same tolerance. MJX compiles for tens of seconds on a CPU: tiny batches, one model."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModuleBase

from bayessim_exp import registry

pytest.importorskip("mujoco.mjx")
from bayessim_exp.rl.compiled_collection import CompiledCollector, actor_arrays, gaussian_actor  # noqa: E402
from bayessim_exp.rl.config import PPOConfig  # noqa: E402
from bayessim_exp.rl.env import SimulatorEnv, distribution_sampler  # noqa: E402
from bayessim_exp.rl.ppo import PPOTrainer, make_agent  # noqa: E402
from bayessim_exp.sim.mjx import MjxConfig, MjxSimulator  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("test_compiled_collection")]  # one worker: one MJX setup
ENVS, STEPS, BATCHES = 3, 8, 2
TOL = 1e-4


class RecordedNoise:
    """The compiled collector's noise source, keeping every draw for the step-by-step reference."""

    def __init__(self, seed: int):
        self.generator, self.drawn = torch.Generator().manual_seed(seed), []

    def __call__(self, shape, device):
        self.drawn.append(torch.randn(shape, generator=self.generator).to(device))
        return self.drawn[-1]


class NoiseFedActor(TensorDictModuleBase):
    """The agent's actor with given noise: action = loc + scale * noise[step], and its log-density."""

    in_keys, out_keys = ["observation"], ["loc", "scale", "action", "action_log_prob"]

    def __init__(self, agent, noise: torch.Tensor):
        super().__init__()
        self.net, self.noise, self.step = agent.actor.module[0], noise, 0

    def forward(self, td):
        td = self.net(td)
        eps = self.noise[self.step]
        self.step += 1
        normal = torch.distributions.Normal(td["loc"], td["scale"])
        action = td["loc"] + td["scale"] * eps
        return td.set("action", action).set("action_log_prob", normal.log_prob(action).sum(-1))


@pytest.fixture(scope="module")
def setup():
    from bayessim_exp import api

    cfg = api.compose(["task=Pendulum", "sim=mjx", "rl=ppo", "task.episode_length=5"])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    mjx = MjxConfig(max_abs_qvel=1.0e4, cache_dir=None, nthread=1, native_below=0, impl="jax",
                    tuning=dict(cfg.sim.tuning))
    sim = MjxSimulator(task, ENVS, mjx)
    train = PPOConfig(**{**cfg.rl.train, "num_envs": ENVS, "rollout_steps": STEPS, "total_steps": ENVS * STEPS * BATCHES,
                         "minibatch_size": 8, "epochs": 1})
    return task, prior, sim, train


def collect_both_ways(sim, agent, sampler, steps: int, batches: int) -> tuple[list, list]:
    """The compiled collector's batches, and the Collector's over SimulatorEnv fed the same noise and seed."""
    from torchrl.collectors import Collector
    from torchrl.envs import TransformedEnv
    from torchrl.envs.transforms import RewardSum

    total = sim.num_envs * steps * batches
    noise = RecordedNoise(1)
    env = SimulatorEnv(sim, sampler, seed=7, draw_steps=steps)
    compiled = list(CompiledCollector(env, agent, steps, total, seed=7, noise=noise))
    env = SimulatorEnv(sim, sampler, seed=7, draw_steps=steps)
    env.set_seed(7)
    policy = NoiseFedActor(agent, torch.cat(noise.drawn))
    collector = Collector(TransformedEnv(env, RewardSum()), policy, frames_per_batch=sim.num_envs * steps,
                          total_frames=total, auto_register_policy_transforms=False)
    policy.step = 0  # the Collector may call its policy once while it is built
    stepwise = list(collector)
    assert len(compiled) == len(stepwise) == batches
    for ours, theirs in zip(compiled, stepwise):
        for key in ("observation", "action", "action_log_prob", ("next", "observation"), ("next", "reward"),
                    ("next", "episode_reward")):
            torch.testing.assert_close(ours[key], theirs[key], atol=TOL, rtol=0, msg=f"{key}")
        for key in (("next", "done"), ("next", "terminated"), ("next", "truncated")):
            assert torch.equal(ours[key], theirs[key]), key
    return compiled, stepwise


def test_compiled_batches_equal_the_collectors(setup):
    task, prior, sim, train = setup
    torch.manual_seed(0)
    agent = make_agent(train, task.obs_dim, task.action_dim, sim.device)  # a GPU on the device machine
    with torch.no_grad():  # a trained-looking normaliser, so that it is exercised
        agent.norm.mean.copy_(torch.tensor([0.5, -0.2, 1.0], device=sim.device))
        agent.norm.var.copy_(torch.tensor([0.3, 0.6, 4.0], device=sim.device))
    compiled, _ = collect_both_ways(sim, agent, distribution_sampler(prior), STEPS, BATCHES)
    # episodes of 5 steps in batches of 8: both batches hold resets with new parameters drawn from the prior
    assert compiled[0]["next", "truncated"].sum() == ENVS and compiled[1]["next", "truncated"].sum() == 2 * ENVS
    assert not compiled[0]["next", "terminated"].any()
    first, after_reset = compiled[0]["observation"][:, 0], compiled[0]["observation"][:, 5]
    assert not torch.allclose(first, after_reset)


def test_a_diverging_slot_ends_its_episode_alike():
    from test_native import spring_task  # noqa: PLC0415  (tests/unit is on sys.path under pytest)

    task = spring_task()  # k = 1e6 blows up; episodes of 200 steps: only a breakdown ends one here
    sim = MjxSimulator(task, 4, MjxConfig(max_abs_qvel=1.0e4, cache_dir=None, nthread=1, native_below=0, impl="jax",
                                          tuning={}))
    rows = torch.tensor([[10.0], [1.0e6], [100.0], [1.0e6]], dtype=torch.float64)
    torch.manual_seed(0)
    agent = make_agent(PPOConfig(**{**_ppo_defaults(), "hidden": [8]}), task.obs_dim, task.action_dim, sim.device)
    compiled, _ = collect_both_ways(sim, agent, lambda n, generator: rows.repeat(n // 4, 1), 50, 2)
    terminated = torch.cat([b["next", "terminated"][..., 0] for b in compiled], 1)
    assert terminated[[0, 2]].sum() == 0 and (terminated[[1, 3]].sum(1) >= 1).all()
    ended = terminated.nonzero()
    rewards = torch.cat([b["next", "reward"][..., 0] for b in compiled], 1)
    assert all(rewards[i, t] == 0.0 for i, t in ended.tolist())  # no reward from a broken-down step


def _ppo_defaults() -> dict:
    from bayessim_exp import api

    return dict(api.compose(["rl=ppo"]).rl.train) | {"num_envs": 4, "rollout_steps": 50, "total_steps": 400}


def test_the_jax_actor_is_the_torch_actor(setup):
    import jax.numpy as jnp

    task, _, _, train = setup
    torch.manual_seed(3)
    agent = make_agent(dataclasses.replace(train, hidden=[16, 8, 4]), task.obs_dim, task.action_dim, "cpu")
    obs, eps = torch.randn(5, task.obs_dim) * 3, torch.randn(5, task.action_dim)
    action, extras = gaussian_actor(actor_arrays(agent, torch.device("cpu")), jnp.asarray(obs.numpy()),
                                    jnp.asarray(eps.numpy()))
    td = agent.actor.module[0](TensorDict({"observation": obs}, [5]))
    expected = td["loc"] + td["scale"] * eps
    torch.testing.assert_close(torch.from_dlpack(action), expected, atol=1e-5, rtol=0)
    log_prob = torch.distributions.Normal(td["loc"], td["scale"]).log_prob(expected).sum(-1)
    torch.testing.assert_close(torch.from_dlpack(extras["action_log_prob"]), log_prob, atol=1e-5, rtol=0)


def test_ppo_trains_through_the_compiled_collection(setup):
    task, prior, sim, train = setup
    torch.manual_seed(0)
    trainer = PPOTrainer(dataclasses.replace(train, collector="compiled"), task.obs_dim, task.action_dim)
    before = [p.detach().clone() for p in trainer.agent.parameters()]
    curve = trainer.train(SimulatorEnv(sim, distribution_sampler(prior), seed=0, draw_steps=STEPS), seed=0)
    assert curve["steps"] == [ENVS * STEPS, 2 * ENVS * STEPS]
    assert all(torch.isfinite(torch.tensor(curve["episode_return"])))
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.agent.parameters()))

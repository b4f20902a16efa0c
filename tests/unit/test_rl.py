"""rl=ppo's pieces: the torchrl environment over a Simulator, the observation normaliser, the collect
policies, the configs, and one short train_policy -> evaluate round outside the pipeline."""

import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.errors import ConfigError
from bayessim_exp.policies import FixedPolicy, FixedPolicyConfig, RandomPolicy


def pendulum_sim(compose, num_envs, overrides=()):
    cfg = compose(["task=Pendulum", *overrides])
    task = registry.build("task", cfg.task)
    return task, registry.build("sim", cfg.sim)(task, num_envs)


def test_env_specs_and_per_slot_parameters_at_reset(compose):
    from torchrl.envs.utils import check_env_specs

    from bayessim_exp.rl.env import SimulatorEnv

    task, sim = pendulum_sim(compose, 4, ["task.episode_length=5"])
    drawn, resets = [], []

    def sampler(n, generator):  # row i of the k-th call: (0.5 + 0.1 k, 0.5 + 0.01 i)
        rows = torch.tensor([[0.5 + 0.1 * len(drawn), 0.5 + 0.01 * i] for i in range(n)], dtype=torch.float64)
        drawn.append(n)
        return rows

    reset = sim.reset
    sim.reset = lambda params, ids, **kw: resets.append((params.clone(), ids.clone())) or reset(params, ids, **kw)
    env = SimulatorEnv(sim, sampler, seed=0, draw_steps=3)
    check_env_specs(env)
    env.set_seed(0)
    drawn.clear(), resets.clear()
    td = env.rollout(12, break_when_any_done=False)
    # every slot truncates at steps 5 and 10; draws come 3 steps (12 rows) per sampler call, one step's
    # rows for the first reset and one step's after each step
    assert td["next", "truncated"].sum().item() == 8 and not td["next", "terminated"].any()
    assert drawn == [12] * 5
    assert [ids.tolist() for _, ids in resets] == [[0, 1, 2, 3]] * 3
    for (params, _), step in zip(resets, (0, 5, 10)):  # slot i takes row i of that step's draws
        call, row = divmod(step, 3)
        torch.testing.assert_close(params, torch.tensor([[0.5 + 0.1 * call, 0.5 + 0.01 * (4 * row + i)]
                                                         for i in range(4)], dtype=torch.float64))
    # resets without a step between them take the same step's rows: here the 12th step's (call 4, row 0)
    env.reset(env.reset().set("_reset", torch.tensor([[True], [False], [False], [True]])))
    assert resets[-1][1].tolist() == [0, 3]
    torch.testing.assert_close(resets[-1][0], torch.tensor([[0.9, 0.5], [0.9, 0.53]], dtype=torch.float64))


def test_diverged_slot_is_terminated(compose):
    from tensordict import TensorDict

    from bayessim_exp.rl.env import SimulatorEnv, fixed_params

    task, sim = pendulum_sim(compose, 2)
    env = SimulatorEnv(sim, fixed_params(task.true_params), seed=0)
    env.reset()
    sim.diverged[1] = True  # as a backend reports a breakdown
    out = env.step(TensorDict({"action": torch.zeros(2, 1)}, [2]))
    assert out["next", "terminated"].squeeze(-1).tolist() == [False, True]
    assert out["next", "reward"][1].item() == 0.0


def test_running_norm_matches_the_data():
    from bayessim_exp.rl.networks import RunningNorm

    norm = RunningNorm(3, clip=100.0)
    gen = torch.Generator().manual_seed(0)
    parts = [torch.randn(50, 3, generator=gen) * torch.tensor([1.0, 10.0, 0.1]) + 5 for _ in range(4)]
    for p in parts:
        norm.update(p)
    data = torch.cat(parts)
    assert torch.allclose(norm.mean, data.mean(0), atol=1e-4)
    assert torch.allclose(norm.var, data.var(0, unbiased=False), rtol=1e-2)  # up to the 1e-4 pseudo-count
    assert torch.allclose(norm(data).std(0, unbiased=False), torch.ones(3), atol=1e-2)


def fixed(signal, **kw):
    values = dict(signal=signal, offset=[0.1], amplitude=[0.5], frequency=[1.0], frequency_end=[3.0],
                  sweep_seconds=2.0, phase=[0.0])
    values.update(kw)
    return FixedPolicy(FixedPolicyConfig(**values), action_dim=2, control_dt=0.05)


def test_fixed_policy_signals():
    obs = torch.zeros(3, 4)
    assert torch.allclose(fixed("constant").act(obs, 7), torch.full((3, 2), 0.6))
    # a 1 Hz sine at t = 0.25 s is at its crest
    assert torch.allclose(fixed("sine").act(obs, 5), torch.full((3, 2), 0.6))
    # a chirp's phase is 2 pi (f0 s + (f1 - f0) s^2 / (2 T)): at s = 1 s, 2 pi * 1.5 -> sin = 0
    assert torch.allclose(fixed("chirp").act(obs, 20), torch.full((3, 2), 0.1), atol=1e-6)
    # ... and the sweep starts again after sweep_seconds
    assert torch.allclose(fixed("chirp").act(obs, 45), fixed("chirp").act(obs, 5))
    per_dim = fixed("constant", offset=[0.0, -0.2], amplitude=[2.0]).act(obs, 0)
    assert per_dim[0].tolist() == pytest.approx([1.0, 1.0])  # clipped to the action bounds
    with pytest.raises(ConfigError, match="action_dim"):
        fixed("constant", offset=[0.0, 0.1, 0.2])


def test_policy_configs_are_checked(compose):
    with pytest.raises(ConfigError, match="signal"):
        registry.build("policy", compose(["policy=fixed", "policy.signal=square"]).policy, action_dim=1, seed=0,
                       control_dt=0.05)
    with pytest.raises(ConfigError, match="random_share"):
        registry.build("policy", compose(["policy=rl_randomized", "policy.random_share=1.5"]).policy, action_dim=1,
                       seed=0)


def test_rl_policies_use_the_actor_with_a_share_of_random_actions(compose):
    def actor(td):  # a deterministic stand-in with the torchrl actor's interface
        return td.set("action", torch.full((td.shape[0], 2), 0.25))

    cfg = compose(["policy=rl"]).policy
    assert isinstance(registry.build("policy", cfg, action_dim=2, seed=0, actor=None), RandomPolicy)
    obs = torch.zeros(4000, 3)
    assert (registry.build("policy", cfg, action_dim=2, seed=0, actor=actor).act(obs, 0) == 0.25).all()
    cfg = compose(["policy=rl_randomized", "policy.random_share=0.3"]).policy
    act = registry.build("policy", cfg, action_dim=2, seed=0, actor=actor).act(obs, 0)
    share = (act != 0.25).all(1).float().mean().item()
    assert 0.27 < share < 0.33


def test_ppo_config_per_task_smoke_and_command_line(compose):
    def train(overrides):
        return registry.parse_params("rl", compose(overrides).rl)[1].train

    assert train(["task=Pendulum", "rl=ppo"]).gamma == 0.9  # conf/rl_task/ppo_Pendulum.yaml
    assert train(["task=Ant", "rl=ppo"]).gamma == 0.99  # conf/rl/ppo.yaml
    assert train(["task=Pendulum", "rl=ppo", "rl.train.gamma=0.8"]).gamma == 0.8
    assert train(["task=Pendulum", "rl=ppo", "debug=smoke"]).total_steps == 512
    assert compose(["rl=none", "debug=smoke"]).rl.name == "none"
    with pytest.raises(ConfigError, match="train_on"):
        registry.parse_params("rl", compose(["rl=ppo", "rl.train_on=uniform"]).rl)
    with pytest.raises(ConfigError, match="total_steps"):
        registry.parse_params("rl", compose(["rl=ppo", "rl.train.total_steps=10"]).rl)


def test_train_evaluate_finetune_outside_the_pipeline(compose, tmp_path):
    from bayessim_exp.components import build_components
    from bayessim_exp.rl.standalone import StandaloneRounds
    from bayessim_exp.run_config import check_run_config

    def rounds(out_dir):
        cfg = compose(["task=Pendulum", "rl=ppo", "debug=smoke", "rl.finetune=true", "rl.evaluate.video_steps=3"])
        comp = build_components(cfg, check_run_config(cfg))
        return StandaloneRounds(cfg, comp, comp.prior, out_dir)

    runner = rounds(tmp_path / "a")
    assert runner.rl.actor(runner.context(1)) is None
    ctx = runner.run_round(1)
    record = runner.rl.record(ctx)
    ret = record["surrogate_real_return"]
    assert ret["min"] <= ret["mean"] <= ret["max"] < 0  # Pendulum's rewards are costs
    assert record["rl_training"]["steps"] == 512
    video = ctx.output("evaluate")["video"]
    if video is not None:  # a GIF where OpenGL works; otherwise the reason was logged
        assert video[:6] == b"GIF89a"
    first = ctx.output("train_policy")["trainer"]
    assert runner.rl.actor(runner.context(2)) is not None  # round 1's actor collects until round 2's is trained
    second = runner.run_round(2).output("train_policy")["trainer"]
    assert second["steps_done"] == 2 * first["steps_done"]  # continued round 1's policy
    again = rounds(tmp_path / "b").run_round(1).output("train_policy")["trainer"]["agent"]
    assert all(torch.equal(first["agent"][k], again[k]) for k in first["agent"])  # seeded by stage name


def test_nominal_values_leave_the_model_as_written(pendulum):
    from bayessim_exp.tasks.parameterized import model_with_params

    model = model_with_params(pendulum, pendulum.spec.nominal)
    assert np.allclose(model.body_mass, pendulum.model.body_mass)
    assert np.allclose(model.body_ipos, pendulum.model.body_ipos)
    heavy = model_with_params(pendulum, np.array([2.0, 1.0]))
    assert heavy.body_mass[1] == pytest.approx(2 * pendulum.model.body_mass[1])


def test_collector_choice_is_checked(compose):
    from bayessim_exp.rl.env import SimulatorEnv, fixed_params
    from bayessim_exp.rl.ppo import PPOTrainer

    with pytest.raises(ConfigError, match="collector='gpu'.*auto, compiled, stepwise"):
        registry.parse_params("rl", compose(["rl=ppo", "rl.train.collector=gpu"]).rl)
    task, sim = pendulum_sim(compose, 4)  # native MuJoCo: no closed loops
    train = registry.parse_params("rl", compose(["task=Pendulum", "rl=ppo", "debug=smoke",
                                                 "rl.train.collector=compiled"]).rl)[1].train
    trainer = PPOTrainer(train, task.obs_dim, task.action_dim)
    with pytest.raises(ConfigError, match="collector=compiled needs sim=mjx"):
        trainer.train(SimulatorEnv(sim, fixed_params(task.spec.nominal), 0), seed=0)

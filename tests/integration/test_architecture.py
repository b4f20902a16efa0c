"""The interfaces hold: a method and a simulator backend from outside the package run through the
pipeline untouched, every prior works, and a run is a function of its seed."""

import json
import textwrap

import pytest
import torch
from omegaconf import OmegaConf, open_dict

from bayessim_exp.pipeline import Pipeline
from bayessim_exp.testing.run_results import without_seconds

pytestmark = pytest.mark.slow

SMOKE = ["debug=smoke", "logging.progress=false"]

# A researcher's module: rejection ABC as an inference method, and a backend that adds sensor noise
# to the native simulator's observations. Neither touches the package.
PLUGIN = textwrap.dedent('''
    import dataclasses

    import torch

    from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
    from bayessim_exp.inference.base import InferenceMethod, real_trajectories
    from bayessim_exp.registry import register
    from bayessim_exp.sim.native import NativeConfig, NativeSimulator
    from bayessim_exp.stages import Stage


    @dataclasses.dataclass
    class RejectionConfig:
        accept: float  # share of simulations kept, the closest to the real summary


    class Rejection(InferenceMethod):
        def __init__(self, cfg, inputs):
            self.cfg, self.inputs = cfg, inputs

        def stages(self):
            return [Stage("simulate", self.simulate), Stage("accept", self.accept, inputs=("simulate", "real"))]

        def proposal(self, ctx):
            return self.inputs.prior

        def simulate(self, ctx):
            theta = self.proposal(ctx).sample((self.inputs.rc.collect.trajectories,),
                                              generator=torch.Generator().manual_seed(ctx.seed))
            traj = self.inputs.sims.rollout(theta, self.inputs.policy(ctx.seed), self.inputs.rc.collect.horizon, ctx.seed)
            return {"theta": theta, "x": self.inputs.summarizer(traj)}

        def accept(self, ctx):
            sims = ctx.output("simulate")
            x_real = self.inputs.summarizer(real_trajectories(ctx)).mean(0)
            scale = sims["x"].std(0).clamp_min(1e-8)
            distance = ((sims["x"] - x_real) / scale).norm(dim=1)
            kept = sims["theta"][distance.argsort()[: max(3, int(self.cfg.accept * len(distance)))]]
            gaussian = GaussianMixture(torch.zeros(1), kept.mean(0, keepdim=True), torch.cov(kept.T)[None])
            return {"posterior": TruncatedMixture(gaussian, self.inputs.prior.low, self.inputs.prior.high, seed=ctx.seed),
                    "kept": len(kept)}

        def posterior(self, ctx):
            return ctx.output("accept")["posterior"]

        def record(self, ctx):
            return {"accepted": ctx.output("accept")["kept"]}


    @register("method", "rejection", RejectionConfig)
    def rejection(cfg, inputs):
        return Rejection(cfg, inputs)


    @dataclasses.dataclass
    class NoisyConfig:
        noise: float  # std of Gaussian sensor noise on every observation


    class NoisySimulator(NativeSimulator):
        def __init__(self, task, num_envs, noise):
            super().__init__(task, num_envs, NativeConfig(nthread=1, max_abs_qvel=1e4))
            self.noise, self.generator = noise, torch.Generator().manual_seed(num_envs)

        def _step(self, actions):
            obs, reward, terminated, broken = super()._step(actions)
            return obs + self.noise * torch.randn(obs.shape, generator=self.generator), reward, terminated, broken


    @register("sim", "noisy", NoisyConfig)
    def noisy(cfg):
        return lambda task, num_envs: NoisySimulator(task, num_envs, cfg.noise)
''')


def test_method_and_backend_from_outside_the_package(compose, tmp_path, monkeypatch):
    (tmp_path / "mylab_rejection.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = compose(SMOKE + ["plugins=[mylab_rejection]", "rounds=1", "collect.trajectories=500"])
    with open_dict(cfg):
        cfg.method = OmegaConf.create({"name": "rejection", "accept": 0.1})
        cfg.sim = OmegaConf.create({"name": "noisy", "noise": 0.01})
    results = Pipeline(cfg, tmp_path / "run").run()
    last = results["rounds"][-1]
    assert results["method"] == "rejection" and last["accepted"] == 50
    assert set(last["seconds"]) == {"real", "simulate", "accept", "score"}
    assert last["log_prob_gain"] > 0  # 50 nearest of 500 prior draws know something about the pendulum


# A researcher's collect policy: full actuation whose sign flips every `period` control steps.
POLICY_PLUGIN = textwrap.dedent('''
    import dataclasses

    import torch

    from bayessim_exp.registry import register


    @dataclasses.dataclass
    class BangBangConfig:
        period: int  # control steps between sign flips


    class BangBang:
        def __init__(self, period, action_dim):
            self.period, self.action_dim = period, action_dim

        def act(self, obs, t):
            sign = 1.0 if (t // self.period) % 2 == 0 else -1.0
            return torch.full((obs.shape[0], self.action_dim), sign)


    @register("policy", "bang_bang", BangBangConfig)
    def bang_bang(cfg, action_dim, **_):
        return BangBang(cfg.period, action_dim)
''')


def test_collect_policy_from_outside_the_package(compose, tmp_path, monkeypatch):
    from bayessim_exp.artifacts import RunDir

    (tmp_path / "mylab_bang_bang.py").write_text(POLICY_PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = compose(SMOKE + ["plugins=[mylab_bang_bang]", "rounds=1"])
    with open_dict(cfg):
        cfg.policy = OmegaConf.create({"name": "bang_bang", "period": 5})
    results = Pipeline(cfg, tmp_path / "run").run()
    assert results["policy"] == "bang_bang"
    # the real system and the simulations were both driven by it
    actions = RunDir(tmp_path / "run").load(1, "real")["traj"]["actions"]
    steps = torch.arange(actions.shape[1])
    assert torch.equal(actions[0, :, 0], torch.where((steps // 5) % 2 == 0, 1.0, -1.0))
    assert results["rounds"][-1]["train_set_size"] > 0


def test_untruncated_gaussian_prior_runs(compose, tmp_path):
    results = Pipeline(compose(SMOKE + ["prior=gaussian", "prior.truncate=false"]), tmp_path).run()
    assert len(results["rounds"]) == 2
    assert all(v > 0 for v in results["rounds"][-1]["posterior_std"].values())


def test_probit_space_asked_for_an_unbounded_prior_names_the_fix(compose, tmp_path):
    from bayessim_exp.errors import ConfigError

    cfg = compose(SMOKE + ["prior=gaussian", "prior.truncate=false", "method.parameter_space=probit"])
    with pytest.raises(ConfigError, match="set method.parameter_space=box"):
        Pipeline(cfg, tmp_path).run()


def test_same_seed_gives_the_same_results(compose, tmp_path):
    cfg = compose(SMOKE + ["seed=3"])
    for run in ("a", "b"):
        Pipeline(cfg, tmp_path / run).run()
    a, b = (json.loads((tmp_path / run / "results.json").read_text()) for run in ("a", "b"))
    assert without_seconds(a) == without_seconds(b)

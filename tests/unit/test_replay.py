"""Replaying recorded trajectories: observation -> state hooks, exact replays, and the replayed check."""

import math

import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.diagnostics.replay import replay
from bayessim_exp.diagnostics.replayed_check import replayed_check
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.sim.trajectories import Trajectories


def _task(compose, name):
    return registry.build("task", compose([f"task={name}"]).task)


def _pool(task):
    return SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=4096)


@pytest.mark.parametrize("name", ["Pendulum", "Cartpole"])
def test_the_state_recovered_from_an_observation_reproduces_it(compose, name):
    task = _task(compose, name)
    sim = _pool(task).get(6)
    obs = sim.reset(np.repeat(task.true_params[None], 6, 0), None, seed=0).double().numpy()
    again = sim.reset(np.repeat(task.true_params[None], 6, 0), None, seed=1, state=task.state_from_observation(obs))
    np.testing.assert_allclose(again.numpy(), obs, atol=1e-6)  # observations are float32


def test_a_task_without_the_hook_says_so(compose):
    task = _task(compose, "Ant")
    assert task.state_from_observation(np.zeros((1, task.obs_dim))) is None
    with pytest.raises(ValueError, match="Ant cannot map an observation"):
        replay(_pool(task), torch.as_tensor(task.true_params)[None], _recorded(task, task.true_params, n=1), torch.arange(1))


def _recorded(task, params, n=3, horizon=20, seed=0):
    sim = _pool(task).get(n)
    return sim.rollout(np.repeat(np.asarray(params)[None], n, 0), RandomPolicy(task.action_dim, seed), horizon, seed=seed)


def test_a_replay_at_the_recording_parameters_is_the_recording(compose):
    task = _task(compose, "Pendulum")
    real = _recorded(task, [1.3, 0.6])
    out = replay(_pool(task), torch.tensor([[1.3, 0.6]] * 3), real, torch.arange(3))
    torch.testing.assert_close(out.states, real.states, atol=1e-5, rtol=0)


def _check(task, real, posterior_mean, prior, summarizer):
    posterior = GaussianMixture(torch.zeros(1), torch.tensor([posterior_mean], dtype=torch.float64),
                                torch.diag(torch.tensor([0.01, 0.002], dtype=torch.float64)) ** 2 * torch.ones(1, 1, 1))
    pool = _pool(task)

    def simulate(theta, which):
        return replay(pool, theta.clamp(prior.low, prior.high), real, which)

    return replayed_check(simulate, real, posterior, prior, summarize=summarizer, num=100, seed=0, alpha=0.01,
                          max_distance_ratio=0.15)


def _rotated(traj, angle: float):
    """The same trajectories with the angle logged `angle` rad off (a log with another zero): no parameter
    of our pendulum reproduces them, since gravity acts on the true angle."""
    cos, sin = traj.states[..., 0], traj.states[..., 1]
    states = traj.states.clone()
    states[..., 0] = cos * np.cos(angle) - sin * np.sin(angle)
    states[..., 1] = sin * np.cos(angle) + cos * np.sin(angle)
    return type(traj)(states, traj.actions, traj.rewards, traj.valid, traj.diverged, traj.dt)


def test_the_replayed_check_passes_a_posterior_at_the_truth_and_finds_one_elsewhere_too_narrow(compose):
    cfg = compose([])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    real = _recorded(task, [1.3, 0.6])
    good = _check(task, real, [1.3, 0.6], prior, summarizer)
    assert good.too_narrow == [] and good.flagged == [] and min(good.p_value) > 0.01
    assert float(good.model_error_covariance.abs().max()) < 1e-3 * float(good.posterior_covariance.abs().max())
    wrong = _check(task, real, [0.8, 0.45], prior, summarizer)
    assert wrong.too_narrow == [0, 1, 2]
    assert wrong.record()["p_value"] == pytest.approx([1 / 101] * 3)


def test_data_no_parameter_reproduces_are_flagged_and_give_a_model_error(compose):
    cfg = compose([])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    real = _rotated(_recorded(task, [1.3, 0.6]), 0.3)
    check = _check(task, real, [1.3, 0.6], prior, summarizer)
    assert check.flagged == [0, 1, 2], check.record()
    assert min(check.excess_ratios) > 0.15 and max(check.residual_p_value) <= 0.01
    # a model error far wider than the posterior: the posterior must widen to hold it
    assert torch.linalg.eigvalsh(check.model_error_covariance - check.posterior_covariance).max() > 0


def _linear_trajectories(z: torch.Tensor) -> Trajectories:
    """Trajectories whose one state row is the summary z [N, F] (summarized by reading it back)."""
    n = len(z)
    return Trajectories(z[:, None].float(), torch.zeros(n, 0, 1), torch.zeros(n, 0), torch.zeros(n, 0, dtype=torch.bool),
                        torch.zeros(n, dtype=torch.bool), 0.05)


def test_the_model_error_is_least_squares_spread_of_each_features_unexplained_part():
    """A simulator whose 6 summaries are exactly linear in 2 parameters (slopes A), and real data with an offset e
    that no parameter explains. The error covariance is the sandwich G^-1 B^T diag(v) B G^-1, v each standardised
    feature's unexplained square (the replays leave none): here computed from A and e alone. An offset in two of the
    six features costs 4 to 10 times less variance than the whole residual put in every feature (r^2 G^-1, the
    rule before) would."""
    A = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0], [0.01, 0.0], [0.0, 0.01]], dtype=torch.float64)
    offset = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.3, -0.2], dtype=torch.float64)
    centre = torch.tensor([[1.0, 0.5]], dtype=torch.float64)
    real = _linear_trajectories(centre @ A.T + offset)
    posterior = GaussianMixture(torch.zeros(1), centre, 0.01 * torch.eye(2, dtype=torch.float64)[None])
    prior = GaussianMixture(torch.zeros(1), centre, torch.eye(2, dtype=torch.float64)[None])
    check = replayed_check(lambda theta, which: _linear_trajectories(theta @ A.T), real, posterior, prior,
                           summarize=lambda traj: traj.states[:, 0].double(), num=400, seed=0, alpha=0.01,
                           max_distance_ratio=0.15)
    assert check.residual_p_value[0] <= 0.01
    g = torch.Generator().manual_seed(0)
    scale = (prior.sample((400,), generator=g) @ A.T).std(0)  # the prior replays' spread, as the check measures it
    B = A / scale[:, None] / math.sqrt(6)  # standardised slopes
    gram = B.T @ B
    hat = B @ torch.linalg.solve(gram, B.T)
    unexplained = (torch.eye(6, dtype=torch.float64) - hat) @ (offset / scale / math.sqrt(6))
    inverse = torch.linalg.inv(gram)
    expected = inverse @ (B.T * unexplained**2) @ B @ inverse
    torch.testing.assert_close(check.model_error_covariance, expected, rtol=0.05, atol=1e-9)
    whole = unexplained.pow(2).sum() * inverse
    assert (torch.diagonal(whole) > 4 * torch.diagonal(check.model_error_covariance)).all()


def test_a_parameter_every_replay_shares_gets_no_slope_and_its_value_as_implied():
    """Seed 19 of a Pendulum calibration study stopped here: every posterior draw of one parameter on the box's
    edge made the linear fit's normal matrix singular. z = 2 theta_0 + noise; theta_1 constant at 2.0."""
    from bayessim_exp.diagnostics.replayed_check import implied_parameters

    g = torch.Generator().manual_seed(0)
    theta = torch.stack([torch.randn(100, dtype=torch.float64, generator=g), torch.full((100,), 2.0, dtype=torch.float64)], 1)
    z = 2 * theta[:, :1] + 0.01 * torch.randn(100, 1, dtype=torch.float64, generator=g)
    implied, residual, _, _, _ = implied_parameters(z, theta, torch.tensor([[1.0]], dtype=torch.float64))
    assert torch.isfinite(implied).all() and torch.isfinite(residual).all()
    assert implied[0, 0] == pytest.approx(0.5 + float(theta[:, 0].mean()) - float(z.mean()) / 2, abs=0.01)
    assert implied[0, 1] == 2.0


def _noisy_linear(A: torch.Tensor, seed: int, std: float = 0.01):
    """A simulator whose summaries are linear in the parameters (slopes A [F, D]) plus Gaussian noise of `std`."""
    g = torch.Generator().manual_seed(seed)
    return lambda theta, which: _linear_trajectories(theta @ A.T + std * torch.randn(len(theta), len(A), generator=g,
                                                                                      dtype=torch.float64))


def _linear_check(A, real, posterior_variance: float, seed: int = 0, modelled=None):
    centre = torch.tensor([[1.0, 0.5]], dtype=torch.float64)
    posterior = GaussianMixture(torch.zeros(1), centre, posterior_variance * torch.eye(2, dtype=torch.float64)[None])
    prior = GaussianMixture(torch.zeros(1), centre, torch.eye(2, dtype=torch.float64)[None])
    return replayed_check(_noisy_linear(A, seed + 1), real, posterior, prior,
                          summarize=lambda traj: traj.states[:, 0].double(), num=400, seed=seed, alpha=0.01,
                          max_distance_ratio=0.15, modelled=modelled)


def test_the_feature_error_is_what_least_squares_leaves_of_an_offset_in_the_summaries_units():
    """Summaries linear in 2 parameters with a little simulation noise, real data with an offset in two of six
    features: what no parameter explains of it, feature by feature, is the offset's residual from the least-squares
    projection onto the slopes (in the standardised features the check fits in), read back in the summaries' own
    units: here computed from A, the offset and the prior replays' spread alone."""
    A = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0], [1.0, -1.0], [0.5, 2.0]], dtype=torch.float64)
    offset = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.3, -0.2], dtype=torch.float64)
    real = _linear_trajectories(torch.tensor([[1.0, 0.5]], dtype=torch.float64) @ A.T + offset)
    check = _linear_check(A, real, 0.01)
    prior = torch.randn(400, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    scale = (prior @ A.T).std(0) * math.sqrt(6)  # standardised feature = summary / scale
    B = A / scale[:, None]
    hat = B @ torch.linalg.solve(B.T @ B, B.T)
    expected = (((torch.eye(6, dtype=torch.float64) - hat) @ (offset / scale)) * scale) ** 2
    # the check's scale is its own 400 prior draws' spread (about 3.5 % off each): a square's and a hat's worth
    torch.testing.assert_close(check.feature_error, expected, rtol=0.2, atol=0)


def test_data_the_simulator_reproduces_leave_no_feature_error():
    """Real summaries that are a simulation like the replays: no feature read as unexplained in 20 checks of 400
    replays each (the bound is Bonferroni's over the features at alpha = 0.01, beyond every replay)."""
    A = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0], [1.0, -1.0], [0.5, 2.0]], dtype=torch.float64)
    centre = torch.tensor([[1.0, 0.5]], dtype=torch.float64)
    read = 0
    for seed in range(20):
        g = torch.Generator().manual_seed(1000 + seed)
        real = _linear_trajectories(centre @ A.T + 0.01 * torch.randn(1, 6, generator=g, dtype=torch.float64))
        read += bool((_linear_check(A, real, 0.01, seed=seed).feature_error > 0).any())
    assert read <= 1


def test_with_an_error_model_the_check_reads_the_parameters_from_the_other_features_and_flags_on_all():
    """A posterior far narrower than an offset in two features: the real data's implied parameters lie outside
    the replays'. With those two features in the error model, the implied parameters are read from the other four,
    as the model trained with that noise reads them: the replays hold the real data (and no model error is left to
    widen for), while what the simulator alone leaves unexplained (residual, its p-value, the flag, the feature
    error) reads the same."""
    A = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0], [1.0, -1.0], [0.5, 2.0]], dtype=torch.float64)
    offset = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.3, -0.2], dtype=torch.float64)
    real = _linear_trajectories(torch.tensor([[1.0, 0.5]], dtype=torch.float64) @ A.T + offset)
    clean = _linear_check(A, real, 1e-4)
    modelled = _linear_check(A, real, 1e-4, modelled=offset != 0)
    assert clean.too_narrow == [0] and modelled.too_narrow == []
    assert float(clean.model_error_covariance.trace()) > 0 and float(modelled.model_error_covariance.trace()) == 0
    assert modelled.residual == clean.residual and modelled.residual_p_value == clean.residual_p_value
    assert modelled.flagged == clean.flagged
    assert torch.equal(modelled.feature_error, clean.feature_error)


class _OneParameterFixed:
    """A posterior whose draws vary the first parameter (about 1.0, sd 0.3) and all share the second (0.5): a probit
    posterior saturated on the box's face."""

    def sample(self, shape, generator=None):
        varying = 1.0 + 0.3 * torch.randn(*shape, generator=generator, dtype=torch.float64)
        return torch.stack([varying, torch.full_like(varying, 0.5)], -1)


def test_a_posterior_with_a_parameter_every_draw_shares_is_too_narrow_for_data_its_replays_do_not_reproduce():
    """Real data a replay at the centre would give plus an offset in a feature no parameter moves (beyond the
    replays' residuals): a posterior varying both parameters holds their implied parameters, one whose draws all
    share the second parameter cannot tell where along it they lie and is too narrow. Its Mahalanobis distance
    ignored that parameter (no spread, no slope) and passed such a posterior collapsed on the box's corner, 0.5 +- 0
    for a pendulum logged at 0.1 kg (test_real_data.py, the pendulum outside the prior's box)."""
    A = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0], [0.0, 0.0]], dtype=torch.float64)
    offset = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.05], dtype=torch.float64)
    real = _linear_trajectories(torch.tensor([[1.0, 0.5]], dtype=torch.float64) @ A.T + offset)
    varying = _linear_check(A, real, 0.09)
    prior = GaussianMixture(torch.zeros(1), torch.tensor([[1.0, 0.5]], dtype=torch.float64),
                            torch.eye(2, dtype=torch.float64)[None])
    fixed = replayed_check(_noisy_linear(A, 1), real, _OneParameterFixed(), prior,
                           summarize=lambda traj: traj.states[:, 0].double(), num=400, seed=0, alpha=0.01,
                           max_distance_ratio=0.15)
    assert varying.residual_p_value == [1 / 401] and fixed.residual_p_value == [1 / 401]
    assert varying.too_narrow == [] and fixed.too_narrow == [0]

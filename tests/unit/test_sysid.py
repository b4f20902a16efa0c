"""method=sysid's pieces on surrogate data with known parameters: mujoco.sysid's least-squares estimate, its
Gaussian (the estimate and sysid's covariance where the data identify a parameter, the prior's spread where they
do not), and the clear errors of what it cannot run on."""

import math

import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.errors import ConfigError, DataError
from bayessim_exp.inference.sysid.fit import fit
from bayessim_exp.inference.sysid.laplace import laplace_gaussian
from bayessim_exp.inference.sysid.residual import ReplayResidual
from bayessim_exp.inference.sysid.starts import best_fit, start_points
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.sim.trajectories import Trajectories

# an extra Pendulum parameter that changes the rod's colour: no observation depends on it
COLOUR = ['+task.parameters.colour={range: [0.0, 0.5], operation: additive, targets: ["geom_rgba[rod,0]"]}',
          "+task.real_params.colour=0.1"]


def pendulum(compose, extra=(), trajectories=2, horizon=50, noise=0.0):
    """Task, prior, simulators and real trajectories at the task's real_params; observations after the start
    get Gaussian noise of `noise` times each observation's spread."""
    cfg = compose(["task=Pendulum", "method=sysid", *extra])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, 64)
    real = sims.get(trajectories).rollout(np.repeat(task.true_params[None], trajectories, 0),
                                          RandomPolicy(task.action_dim, 0), horizon, 5)
    if noise > 0:
        states = real.states.clone()
        spread = states.reshape(-1, task.obs_dim).std(0)
        states[:, 1:] += noise * spread * torch.randn(states[:, 1:].shape, generator=torch.Generator().manual_seed(1))
        real = Trajectories(states, real.actions, real.rewards, real.valid, real.diverged, real.dt)
    return cfg, task, prior, sims, real


def identify(cfg, task, prior, sims, real):
    _, sysid_cfg = registry.parse_params("method", cfg.method)
    residual = ReplayResidual(sims, real, task.spec.low, task.spec.high, sysid_cfg.observed)
    start = ((prior.mean - prior.low) / (prior.high - prior.low)).numpy()
    result = fit(residual, task.spec.names, start, sysid_cfg)
    gaussian = laplace_gaussian(result, prior.mean, prior.stddev, prior.low, prior.high, sysid_cfg.min_noise_std,
                                sysid_cfg.identified_below)
    return result, gaussian


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_noisy_observations_give_the_truth_within_a_few_stated_standard_deviations(compose):
    cfg, task, prior, sims, real = pendulum(compose, noise=0.05)
    result, gaussian = identify(cfg, task, prior, sims, real)
    truth = torch.as_tensor(task.true_params)
    std = gaussian.cov.diagonal().sqrt()
    z = (gaussian.mean - truth) / std
    assert z.abs().max() < 4, z
    assert (std < 0.05 * prior.stddev).all()  # and the data say much more than the prior
    # sysid's noise estimate is the noise added (above the floor, so it is the one used)
    assert result.noise_var ** 0.5 == pytest.approx(0.05, rel=0.15)
    assert gaussian.noise_std == pytest.approx(result.noise_var ** 0.5)
    # where the data dominate, the Gaussian is sysid's estimate
    torch.testing.assert_close(gaussian.mean, torch.as_tensor(result.estimate) * (prior.high - prior.low) + prior.low,
                               atol=0.1 * float(std.min()), rtol=0)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_noise_free_observations_give_the_truth_and_the_floored_noise(compose):
    cfg, task, prior, sims, real = pendulum(compose)
    result, gaussian = identify(cfg, task, prior, sims, real)
    estimate = torch.as_tensor(result.estimate) * (prior.high - prior.low) + prior.low
    torch.testing.assert_close(estimate, torch.as_tensor(task.true_params), atol=1e-6, rtol=0)
    assert result.noise_var ** 0.5 < 1e-6  # float32 rounding: what the floor is for
    assert gaussian.noise_std == cfg.method.min_noise_std
    # the floor, not float32 rounding, sets the spread: still far below the prior's
    assert (gaussian.cov.diagonal().sqrt() < 0.01 * prior.stddev).all()


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_a_fit_stuck_in_a_local_minimum_from_the_prior_mean_is_left_for_a_screened_start(compose):
    # this truth and excitation: Gauss-Newton from the prior's mean stops with residuals as large as the signal
    cfg, task, prior, sims, _ = pendulum(compose, ["task.real_params.mass=0.598", "task.real_params.length=0.390"])
    real = sims.get(1).rollout(task.true_params[None], RandomPolicy(1, 3), 50, 5)
    _, sysid_cfg = registry.parse_params("method", cfg.method)
    residual = ReplayResidual(sims, real, task.spec.low, task.spec.high, None)
    mean = ((prior.mean - prior.low) / (prior.high - prior.low)).numpy()
    stuck = fit(residual, task.spec.names, mean, sysid_cfg)
    assert stuck.noise_var ** 0.5 > 0.5
    starts = start_points(residual, mean, prior, sysid_cfg, torch.Generator().manual_seed(0))
    assert len(starts) == sysid_cfg.starts and (starts[0] == mean).all()
    found = best_fit(residual, task.spec.names, starts, sysid_cfg)
    np.testing.assert_allclose(residual.theta(found.estimate), task.true_params, atol=1e-6)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_a_parameter_no_observation_depends_on_keeps_the_prior_spread(compose):
    cfg, task, prior, sims, real = pendulum(compose, COLOUR, noise=0.05)
    result, gaussian = identify(cfg, task, prior, sims, real)
    c = task.spec.names.index("colour")
    assert math.isinf(result.unit_noise_std[c])  # sysid: not identifiable from these data
    assert math.isfinite(result.unit_noise_std[:c].max())
    assert gaussian.identified.tolist() == [True, True, False]
    assert float(gaussian.cov[c, c].sqrt()) == pytest.approx(float(prior.stddev[c]), rel=1e-6)
    assert float(gaussian.mean[c]) == pytest.approx(float(prior.mean[c]), abs=1e-9)
    torch.testing.assert_close(gaussian.cov[c, :c], torch.zeros(c, dtype=torch.float64), atol=1e-12, rtol=0)
    # the others are identified as without it
    truth = torch.as_tensor(task.true_params)
    std = gaussian.cov.diagonal().sqrt()
    assert ((gaussian.mean - truth) / std)[:c].abs().max() < 4


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_parameters_that_only_trade_off_against_each_other_keep_the_prior_spread(compose):
    # a second mass scaling the same body: the data fix only the product of the two
    trade = ['+task.parameters.mass2={range: [0.5, 2.0], operation: scaling, targets: ["body_mass[pole]", '
             '"body_inertia[pole]"]}', "+task.real_params.mass2=1.0"]
    cfg, task, prior, sims, real = pendulum(compose, trade)
    result, gaussian = identify(cfg, task, prior, sims, real)
    estimate = torch.as_tensor(result.estimate) * (prior.high - prior.low) + prior.low
    assert float(estimate[0] * estimate[2]) == pytest.approx(1.0, abs=1e-4)  # the product, exactly
    assert gaussian.identified.tolist() == [False, True, False]
    torch.testing.assert_close(gaussian.cov.diagonal().sqrt()[[0, 2]], prior.stddev[[0, 2]].double())
    assert float(gaussian.cov[0, 2]) == 0.0
    z = (gaussian.mean - torch.as_tensor(task.true_params)) / gaussian.cov.diagonal().sqrt()
    assert z.abs().max() < 3


def test_partial_observations_fit_the_named_ones_only(compose):
    cfg, task, prior, sims, real = pendulum(compose, noise=0.05)
    residual = ReplayResidual(sims, real, task.spec.low, task.spec.high, ["theta_dot"])
    assert residual.size == real.num * real.horizon
    with pytest.raises(ConfigError, match="did you mean theta_dot"):
        ReplayResidual(sims, real, task.spec.low, task.spec.high, ["theta_dott"])


def test_fewer_observed_values_than_parameters_are_refused_before_simulating(compose):
    cfg, task, prior, sims, real = pendulum(compose, trajectories=1, horizon=2)
    residual = ReplayResidual(sims, real, task.spec.low, task.spec.high, ["theta_dot"])
    _, sysid_cfg = registry.parse_params("method", cfg.method)
    with pytest.raises(DataError, match="2 observed values cannot determine 2 parameters"):
        fit(residual, task.spec.names, np.full(2, 0.5), sysid_cfg)
    assert residual.simulations == 0


def test_a_task_that_cannot_restart_from_an_observation_is_refused(compose, tmp_path):
    with pytest.raises(ConfigError, match="state_from_observation"):
        Pipeline(compose(["method=sysid", "task=BallBalance", "debug=smoke"]), tmp_path)


def test_without_sysid_s_dependencies_the_error_names_the_extra(compose, tmp_path, monkeypatch):
    import mujoco.sysid

    monkeypatch.delattr(mujoco.sysid, "optimize")  # what `import mujoco.sysid` holds without mujoco[sysid]
    with pytest.raises(ConfigError, match=r"bayessim_exp\[sysid\]"):
        Pipeline(compose(["method=sysid", "debug=smoke"]), tmp_path)

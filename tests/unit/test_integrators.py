"""Integrators as a nuisance of BayesSim's simulations (sim/integrators.py): slots that alternate between the
model's own integrator and another, what method.integrators=auto chooses for a run, and the refusals."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

from bayessim_exp.errors import ConfigError
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.policies import Policy
from bayessim_exp.sim import integrators
from bayessim_exp.sim.native import NativeConfig, NativeSimulator
from bayessim_exp.sim.pool import SimulatorPool

CONFIG = NativeConfig(nthread=1, max_abs_qvel=1.0e4)


class Zeros(Policy):
    def act(self, obs: torch.Tensor, t: int) -> torch.Tensor:
        return torch.zeros(obs.shape[0], 1)


def _states(pool: SimulatorPool, rows: int) -> torch.Tensor:
    """The pendulum released from 2 rad at its nominal parameters in every row, 40 control steps."""
    params = np.tile(pool.task.spec.nominal, (rows, 1))
    state = {"qpos": np.full((rows, 1), 2.0), "qvel": np.zeros((rows, 1))}
    return pool.rollout(params, Zeros(), horizon=40, seed=0, state=state).states


def test_slots_alternate_between_the_integrators_named(pendulum):
    pool = SimulatorPool(lambda t, n: NativeSimulator(t, n, CONFIG), pendulum, chunk=3)
    own, rk4 = _states(pool, 1)[0], _states(pool.alternating(["RK4"]), 1)[0]
    assert (own - rk4).abs().max() > 1e-3  # the pendulum's MJCF integrates with implicitfast at 10 ms
    alternating = _states(pool.alternating(["model", "RK4"]), 7)  # chunks of 3, 3 and 1: slot by slot in each
    for row, expected in zip(alternating, [own, rk4, own, own, rk4, own, own]):
        torch.testing.assert_close(row, expected)


def test_the_model_s_own_integrator_alone_is_the_pool_itself(pendulum):
    pool = SimulatorPool(lambda t, n: NativeSimulator(t, n, CONFIG), pendulum, chunk=3)
    assert pool.alternating(["model"]) is pool and pool.alternating(()) is pool


@pytest.mark.parametrize(("overrides", "expected"), [
    ([], ("model",)),  # our own simulator's data
    (["real=file", "real.path=robot.npz"], ("model", "RK4")),  # a robot's
    (["real=csv", "real.path=logs"], ("model", "RK4")),
    (["method.integrators=[model,Euler]"], ("model", "Euler")),  # asked for
    (["method=sysid"], ()),  # a method without them
])
def test_auto_alternates_with_rk4_for_recorded_data_only(compose, monkeypatch, overrides, expected):
    monkeypatch.setattr(integrators, "_SAID", set())
    # sim=native: sim=auto on a machine with a GPU simulates on MJX (the next test)
    assert integrators.for_run(compose(["sim=native", *overrides])) == expected


def test_on_mjx_auto_keeps_the_model_s_integrator_and_says_so_once(compose, monkeypatch, caplog):
    monkeypatch.setattr(integrators, "_SAID", set())
    cfg = compose(["sim=mjx", "real=file", "real.path=robot.npz"])
    with caplog.at_level(logging.WARNING, logger="bayessim_exp.sim.integrators"):
        assert integrators.for_run(cfg) == ("model",)
        assert integrators.for_run(cfg) == ("model",)
    assert len(caplog.records) == 1 and "compiles one integrator" in caplog.records[0].message


@pytest.mark.parametrize(("overrides", "message"), [
    (["sim=mjx", "method.integrators=[model,RK4]"], r"MJX compiles one integrator.*sim=native"),
    (["method.integrators=[model,rk4]"], r"model, Euler, RK4, implicit, implicitfast"),
    (["method.integrators=RK4"], r"give auto or a list"),
])
def test_integrators_that_cannot_run_are_refused_before_any_simulation(compose, tmp_path, monkeypatch, overrides,
                                                                        message):
    def refuse(*args, **kwargs):
        raise AssertionError("simulated before the config was checked")

    monkeypatch.setattr(SimulatorPool, "rollout", refuse)
    with pytest.raises(ConfigError, match=message):
        Pipeline(compose(overrides), tmp_path)


def test_a_backend_with_one_compiled_integrator_refuses_to_alternate():
    """Simulator's default, which MjxSimulator keeps: integrators.for_run refuses such a run first."""
    from bayessim_exp.sim.base import Simulator

    with pytest.raises(ConfigError, match="one integrator.*sim=native"):
        Simulator.alternate_integrators(object(), ["model", "RK4"])

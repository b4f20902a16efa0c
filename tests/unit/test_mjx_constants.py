"""The device reset of sim=mjx: field values (ParamSpec.field_values with jax.numpy) and the constants
mj_setConst derives (mjx_constants) equal mujoco.batch's set_const for random parameter sets; trajectories
equal those of the host path (every constant from mujoco.batch); a reset changes the reset slots' leaves
only. The constants alone compile in seconds on a CPU, contact tasks included (no mjx.step)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.policies import RandomPolicy

pytest.importorskip("mujoco.mjx")
from bayessim_exp.sim import mjx_constants  # noqa: E402
from bayessim_exp.sim.mjx import MjxConfig, MjxSimulator  # noqa: E402
from bayessim_exp.sim.mjx_constants import host_reasons  # noqa: E402
from bayessim_exp.tasks.params import model_field  # noqa: E402

pytestmark = pytest.mark.slow
MJX = MjxConfig(max_abs_qvel=1.0e4, cache_dir=None, nthread=1, native_below=0, impl="auto", tuning={})
# float32 on the device against float64 MuJoCo: inv(M) of the humanoid (23 dofs, masses from 0.1 to 8 kg)
# loses more digits than the small models' (measured max relative error 2.2e-5; the others below 3e-6)
RTOL = {"Pendulum": 1e-5, "Cartpole": 1e-5, "BallBalance": 1e-5, "Ingenuity": 1e-5, "Humanoid": 1e-4}


def mjx_for(compose, name):
    """MJX's settings above with the task's tuning (conf/mjx_tuning)."""
    return dataclasses.replace(MJX, tuning=dict(compose([f"task={name}", "sim=mjx"]).sim.tuning))


def params_for(task, n, seed):
    return np.random.default_rng(seed).uniform(task.spec.low, task.spec.high, (n, task.spec.dim))


# the larger models compile for tens of seconds each on a CPU: make test-mjx
@pytest.mark.parametrize("name", [n if n in ("Pendulum", "Cartpole") else pytest.param(n, marks=pytest.mark.mjx)
                                  for n in RTOL])
def test_device_leaves_equal_mujoco_set_const(compose, name):
    task = registry.build("task", compose([f"task={name}"]).task)
    n = 6
    params = params_for(task, n, seed=3)
    sim = MjxSimulator(task, n, mjx_for(compose, name))
    warp_shared = {"dof_M0"} if sim.impl.name == "warp" else set()
    assert not sim._host  # every varying constant of these tasks is computed on the device
    leaves = sim.jax.jit(sim._slot_leaves)(sim.jnp.asarray(params, sim.jnp.float32))
    batch = mujoco.batch.Batch(task.model, n, nthread=1)
    values = task.spec.field_values(task.model, params)
    for field, vals in values.items():
        batch.expand(field)[:] = vals.reshape(batch.expand(field).shape)
    batch.set_const()
    constants = set(leaves) - set(values)
    # MuJoCo Warp keeps dof_M0 one for all worlds (MjxSimulator leaves it nominal there)
    assert {"body_subtreemass", "body_invweight0", "dof_invweight0"} | ({"dof_M0"} - warp_shared) <= constants
    for leaf, got in leaves.items():
        expected = values[leaf] if leaf in values else batch.expanded(leaf)
        expected = np.broadcast_to(getattr(task.model, leaf), got.shape) if expected is None else expected
        assert got.dtype == sim.leaves[leaf].dtype
        np.testing.assert_allclose(np.asarray(got), expected.reshape(got.shape), rtol=RTOL[name], atol=1e-6, err_msg=leaf)


@pytest.mark.parametrize("name", ["Pendulum", "Cartpole"])
def test_trajectories_equal_the_host_path_and_resets_touch_their_slots_only(compose, monkeypatch, name):
    task = registry.build("task", compose([f"task={name}"]).task)
    params = params_for(task, 3, seed=4)
    device = MjxSimulator(task, 3, mjx_for(compose, name))
    with monkeypatch.context() as patch:  # every constant through mujoco.batch's set_const, as before the port
        patch.setattr(mjx_constants, "host_reasons", lambda m, names: dict.fromkeys(names, "test"))
        host = MjxSimulator(task, 3, mjx_for(compose, name))
    assert not device._host and set(host._host) == set(device._constants.names) != set()
    # a first reset with nominal parameters in every slot: set_const leaves the constants shared, and the
    # host copies take the model's
    host.reset(np.tile(task.spec.nominal, (3, 1)), None)
    for leaf in host._host:
        nominal = np.asarray(model_field(host.nominal, leaf))
        np.testing.assert_allclose(np.asarray(host.leaves[leaf]), np.broadcast_to(nominal, (3,) + nominal.shape),
                                   rtol=1e-6, err_msg=leaf)
    a = device.rollout(params, RandomPolicy(task.action_dim, 1), 10, seed=2)
    b = host.rollout(params, RandomPolicy(task.action_dim, 1), 10, seed=2)
    for leaf in host.leaves:
        np.testing.assert_allclose(np.asarray(device.leaves[leaf]), np.asarray(host.leaves[leaf]), rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(a.states, b.states, atol=1e-5, rtol=0)
    torch.testing.assert_close(a.rewards, b.rewards, atol=1e-4, rtol=1e-5)
    # slot 1 takes slot 0's parameters; slots 0 and 2 keep theirs
    before = {k: np.asarray(v) for k, v in device.leaves.items()}
    device.reset(params[[0]], torch.tensor([1]))
    for leaf, old in before.items():
        new = np.asarray(device.leaves[leaf])
        np.testing.assert_array_equal(new[[0, 2]], old[[0, 2]], err_msg=leaf)
        np.testing.assert_array_equal(new[1], old[0], err_msg=leaf)


def test_features_outside_the_port_send_their_constants_to_the_host():
    xml = """<mujoco><worldbody><body><joint name="j" type="hinge"/><geom size="0.1" mass="1"/></body></worldbody>
             <actuator><motor joint="j" armature="0.5"/></actuator></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    names = ["body_subtreemass", "dof_M0", "actuator_acc0", "geom_fluid"]
    reasons = host_reasons(m, names)
    assert set(reasons) == {"dof_M0", "actuator_acc0", "geom_fluid"}
    assert "armature" in reasons["dof_M0"] and "not in the JAX port" in reasons["geom_fluid"]
    m.actuator_armature[:] = 0
    assert set(host_reasons(m, names)) == {"geom_fluid"}

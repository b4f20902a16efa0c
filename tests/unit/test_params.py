"""ParamSpec: targets resolve to the intended model entries and land in every environment."""

import mujoco
import numpy as np
import pytest

from bayessim_exp.errors import ConfigError
from bayessim_exp.sim.native import NativeSimulator
from bayessim_exp.tasks.params import ParamSpec

XML = """
<mujoco>
  <worldbody>
    <body name="upper"><joint name="shoulder" type="hinge" damping="0.5"/>
      <geom name="g_upper" type="capsule" size="0.05 0.2" mass="2"/>
      <body name="lower" pos="0 0 -0.4"><joint name="elbow" type="hinge" damping="0.25"/>
        <geom name="g_lower" type="box" size="0.05 0.05 0.2" mass="1" friction="0.8 0.01 0.001"/>
      </body>
    </body>
    <body name="ball" pos="1 0 0"><freejoint name="free"/><geom type="sphere" size="0.1" mass="0.3"/></body>
  </worldbody>
  <actuator>
    <position name="p_shoulder" joint="shoulder" kp="10"/>
    <position name="p_elbow" joint="elbow" kp="5"/>
  </actuator>
</mujoco>"""


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(XML)


def spec_of(model, **params):
    return ParamSpec.from_config(params, model)


def test_written_fields_read_back_per_environment(model):
    spec = spec_of(
        model,
        lower_mass={"range": [0.5, 3.0], "targets": ["body_mass[lower]", "body_inertia[lower]"]},
        damping={"range": [0.0, 2.0], "operation": "additive", "targets": ["dof_damping[*]"]},
        kp={"range": [0.5, 2.0], "targets": ["actuator_gainprm[*,0]", "actuator_biasprm[*,1]"]},
        friction={"range": [0.2, 1.5], "operation": "set", "targets": ["geom_friction[g_lower,0]"]},
        gravity={"range": [-12.0, -8.0], "operation": "set", "targets": ["opt.gravity[2]"]},
    )
    values = np.array([[0.5, 0.0, 0.5, 0.2, -8.0], [2.0, 1.0, 2.0, 1.5, -12.0], [3.0, 2.0, 1.0, 0.9, -9.81]])
    sim = NativeSimulator.__new__(NativeSimulator)  # only the batch and task are needed here
    sim.batch, sim.model = mujoco.batch.Batch(model, 3, nthread=1), model
    sim.num_envs = 3
    sim.task = type("T", (), {"spec": spec, "model": model})()
    sim.set_params(values, np.arange(3))
    b = sim.batch
    lower = model.body("lower").id
    np.testing.assert_allclose(b.expanded("body_mass")[:, lower], model.body_mass[lower] * values[:, 0])
    np.testing.assert_allclose(b.expanded("body_inertia")[:, lower], model.body_inertia[lower] * values[:, [0]])
    upper = model.body("upper").id
    np.testing.assert_allclose(b.expanded("body_mass")[:, upper], model.body_mass[upper])  # untouched
    np.testing.assert_allclose(b.expanded("dof_damping")[:, :2], model.dof_damping[:2] + values[:, [1]])
    np.testing.assert_allclose(b.expanded("dof_damping")[:, 2:], model.dof_damping[None, 2:] + values[:, [1]])  # free joint's 6 dofs
    np.testing.assert_allclose(b.expanded("actuator_gainprm")[:, :, 0], model.actuator_gainprm[:, 0] * values[:, [2]])
    # position actuators stay consistent: bias = -kp
    np.testing.assert_allclose(b.expanded("actuator_biasprm")[:, :, 1], -b.expanded("actuator_gainprm")[:, :, 0])
    g = model.geom("g_lower").id
    np.testing.assert_allclose(b.expanded("geom_friction")[:, g, 0], values[:, 3])
    np.testing.assert_allclose(b.expanded("geom_friction")[:, g, 1:], np.broadcast_to(model.geom_friction[g, 1:], (3, 2)))
    np.testing.assert_allclose(b.expanded("opt.gravity")[:, 2], values[:, 4])
    # set_const ran: subtree masses follow the new link masses
    np.testing.assert_allclose(b.expanded("body_subtreemass")[:, upper], model.body_mass[upper] + model.body_mass[lower] * values[:, 0])


def test_scaling_uses_nominal_and_power(model):
    spec = spec_of(model, length={"range": [0.1, 0.8], "nominal": 0.4,
                                  "targets": ["geom_size[g_lower,2]", {"field": "body_inertia[lower,0]", "power": 2}]})
    out = spec.field_values(model, np.array([[0.8]]))
    g, b = model.geom("g_lower").id, model.body("lower").id
    assert out["geom_size"][0, g, 2] == pytest.approx(2 * model.geom_size[g, 2])
    assert out["body_inertia"][0, b, 0] == pytest.approx(4 * model.body_inertia[b, 0])
    assert out["body_inertia"][0, b, 1] == pytest.approx(model.body_inertia[b, 1])


@pytest.mark.parametrize("target, message", [
    ("body_mass[lowr]", "closest valid: lower"),
    ("body_mas[lower]", "closest valid: body_mass"),
    ("dof_damping[elbw]", "closest valid: elbow"),
    ("geom_friction[g_lower,7]", "out of range"),
    ("body_mass[nothing_like_it_*]", "matches no body"),
])
def test_bad_targets_name_the_closest_valid_names(model, target, message):
    with pytest.raises(ConfigError, match="closest valid|out of range|matches no") as err:
        spec_of(model, p={"range": [0, 1], "targets": [target]})
    assert message in str(err.value)


def test_bad_operation_range_and_keys(model):
    with pytest.raises(ConfigError, match="operation 'scale' not allowed; allowed: scaling, additive, set"):
        spec_of(model, p={"range": [0, 1], "operation": "scale", "targets": ["body_mass[lower]"]})
    with pytest.raises(ConfigError, match="low < high"):
        spec_of(model, p={"range": [2, 1], "targets": ["body_mass[lower]"]})
    # a per-parameter family would be silently ignored: the prior group chooses it for every range
    with pytest.raises(ConfigError, match="'distribution' is not a parameter key; the prior config group"):
        spec_of(model, p={"range": [1, 2], "distribution": "loguniform", "targets": ["body_mass[lower]"]})
    with pytest.raises(ConfigError, match=r"unknown keys \['rnage'\]; allowed: range, targets, operation, nominal"):
        spec_of(model, p={"rnage": [1, 2], "range": [1, 2], "targets": ["body_mass[lower]"]})

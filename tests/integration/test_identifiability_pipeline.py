"""The identifiability report in a run: a parameter with no effect on the observations is flagged before the fit,
and results.json holds the report beside each round's contraction."""

import pytest

from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow

# the rod's colour: a model field that no observation depends on
COLOUR = ['+task.parameters.colour={range:[0.5,1.5],operation:scaling,targets:["geom_rgba[rod,0]"]}',
          "+task.real_params.colour=1.0"]


def test_a_parameter_that_moves_nothing_is_flagged_and_the_others_are_not(compose, tmp_path):
    results = Pipeline(compose(["task=Pendulum", "debug=smoke", *COLOUR]), tmp_path).run()
    first = results["rounds"][0]["identifiability"]
    assert first["local"]["no_effect"] == ["colour"]
    assert first["local"]["rms"]["mass"] > 0.01 and first["local"]["rms"]["length"] > 0.01
    assert set(first["r2"]) == {"mass", "length", "colour"}
    assert results["rounds"][1]["identifiability"]["local"] is None  # the local view is round 1's
    last = results["rounds"][-1]
    for name, value in last["contraction"].items():
        assert value == pytest.approx(1 - (last["posterior_std"][name] / last["prior_std"][name]) ** 2)

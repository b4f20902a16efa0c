"""real=file: a malformed or surprising file is reported when the run is built, before any simulation,
with what to do about it; results.json stays strict JSON; a changed file is not silently reused."""

import json
import logging

import numpy as np
import pytest

from bayessim_exp.artifacts import RunDir
from bayessim_exp.errors import ConfigError, DataError
from bayessim_exp.pipeline import Pipeline


def _file(tmp_path, n=2, steps=30, name="robot.npz", **overrides):
    rng = np.random.default_rng(0)
    theta = rng.uniform(-np.pi, np.pi, (n, steps + 1))
    arrays = {"states": np.stack([np.cos(theta), np.sin(theta), rng.normal(size=(n, steps + 1))], -1),
              "actions": rng.uniform(-1, 1, (n, steps, 1)), "dt": np.array(0.05)}
    arrays.update(overrides)
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def _build(compose, tmp_path, path, *extra):
    return Pipeline(compose(["real=file", f"real.path={path}", "debug=smoke", *extra]), tmp_path / "run")


@pytest.mark.parametrize("change, message", [
    ({"actions": np.full((2, 30, 1), 1.5)}, r"control range \(\[-2, 2\] for Pendulum\).*divide a symmetric torque"),
    ({"dt": np.array(0.01)}, r"dt=0.01 s but task Pendulum runs at 0.05 s; resample"),
    ({"states": np.zeros((31, 3)), "actions": np.zeros((30, 1))}, r"without its leading axis.*states\[None\]"),
    ({"states": np.zeros((2, 11, 3)), "actions": np.zeros((2, 10, 1))}, r"10 steps, fewer than .*collect.horizon=10"),
    ({"states": np.where(np.arange(31)[None, :, None] == 17, np.nan, np.zeros((2, 31, 3)))},
     r"states\[0, 17, 0\] = nan \(trajectory 0, step 17, cos_theta; 6 non-finite value\(s\) in states\); drop or"),
    ({"actions": np.where(np.arange(30)[None, :, None] == 3, np.inf, np.zeros((2, 30, 1)))},
     r"actions\[0, 3, 0\] = inf \(trajectory 0, step 3, torque; 2 non-finite"),
])
def test_a_malformed_file_is_refused_before_any_simulation_saying_how_to_fix_it(compose, tmp_path, monkeypatch,
                                                                               change, message):
    monkeypatch.setattr("bayessim_exp.sim.native.NativeSimulator.rollout", lambda *a, **k: pytest.fail("simulated"))
    with pytest.raises(DataError, match=message):
        _build(compose, tmp_path, _file(tmp_path, **change))


def test_surprising_but_usable_files_are_reported(compose, tmp_path, caplog):
    caplog.set_level(logging.WARNING)
    path = _file(tmp_path, steps=40, params=np.array([1.0, 0.5]), param_names=np.array(["m", "l"]))
    pipeline = _build(compose, tmp_path, path)
    assert pipeline.real_source.true_params is None
    assert "params are given for ['m', 'l'] but task Pendulum infers ['mass', 'length']" in caplog.text
    assert "trajectories have 40 steps; only the first collect.horizon=20 are used" in caplog.text


def test_true_values_outside_the_prior_are_reported_and_results_stay_strict_json(compose, tmp_path, caplog):
    caplog.set_level(logging.WARNING)
    path = _file(tmp_path, params=np.array([3.0, 0.5]), param_names=np.array(["mass", "length"]))
    _build(compose, tmp_path, path)
    assert "outside the prior's box (mass=3 not in [0.5, 2])" in caplog.text
    run_dir = RunDir(tmp_path / "json")
    run_dir.write_json("results.json", {"gain": float("nan"), "rounds": [{"lp": -float("inf"), "ok": 1.5}]})
    text = (tmp_path / "json" / "results.json").read_text()
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {"gain": None, "rounds": [{"lp": None, "ok": 1.5}]}


def test_a_run_dir_made_from_other_data_is_refused(compose, tmp_path):
    path = _file(tmp_path)
    _build(compose, tmp_path, path)
    _build(compose, tmp_path, path)  # the same contents resume
    _file(tmp_path, n=3)  # same path, new contents
    with pytest.raises(ConfigError, match="made from other real data.*the file changed"):
        _build(compose, tmp_path, path)


def _raw(tmp_path, content):
    path = tmp_path / "robot.npz"
    path.write_bytes(content)
    return path


@pytest.mark.parametrize("content, message", [
    (b"time,theta\n0,0.1\n", r"not an npz file \(17 bytes, beginning b'time,the'\)"),
    (b"", r"not an npz file \(0 bytes"),
    ("npy", r"a single \.npy array, not an npz archive"),
    ("truncated", r"a damaged npz file \(BadZipFile"),
    ("object", r"array 'states' holds Python objects \(dtype=object\), which are not read"),
])
def test_an_unreadable_file_is_named_without_numpys_pickle_advice(compose, tmp_path, content, message):
    import io

    good = _file(tmp_path, name="good.npz").read_bytes()
    if content == "npy":
        buffer = io.BytesIO()
        np.save(buffer, np.zeros((2, 31, 3)))
        content = buffer.getvalue()
    elif content == "truncated":
        content = good[: len(good) // 2]
    elif content == "object":
        buffer = io.BytesIO()
        np.savez(buffer, states=np.array([{"theta": 0.1}], dtype=object), actions=np.zeros((2, 30, 1)))
        content = buffer.getvalue()
    with pytest.raises(DataError, match=message) as error:
        _build(compose, tmp_path, _raw(tmp_path, content))
    assert "allow_pickle" not in str(error.value) and "unsafely" not in str(error.value)

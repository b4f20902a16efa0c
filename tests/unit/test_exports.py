"""Exports without a pipeline: the MJCF with parameters written in, per-parameter quantiles, the torch.distributions
view (and sbi's process_prior on it), which round's distribution a run handed on, and the export command's refusals
of bad input before any compute. tests/integration/test_export.py exports a real run."""

import json
import warnings

import mujoco
import numpy as np
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.api import Run, load_run
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.torch_view import TorchDistribution
from bayessim_exp.export import main as export_main
from bayessim_exp.tasks.parameterized import mjcf_with_params, model_with_params, write_mjcf

F64 = torch.float64


def _field(model, name):
    return np.asarray(getattr(model.opt, name[4:]) if name.startswith("opt.") else getattr(model, name))


def test_the_pendulums_mjcf_holds_the_values_where_the_spec_puts_them(pendulum, tmp_path):
    # pendulum.xml: pole mass 1, diaginertia 0.0833333 0.0833333 0.0001, com at z=0.5, rod half-length 0.5
    path = write_mjcf(pendulum, np.array([1.7, 0.6]), tmp_path / "p.xml", "mass=1.7 -- length=0.6")
    model = mujoco.MjModel.from_xml_path(str(path))
    pole = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "pole")
    rod = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "rod")
    assert model.body_mass[pole] == pytest.approx(1.7, rel=1e-5)
    assert model.geom_size[rod, 1] == pytest.approx(0.3, rel=1e-5)
    assert model.body_ipos[pole, 2] == pytest.approx(0.3, rel=1e-5)
    assert model.body_inertia[pole] == pytest.approx([0.0833333 * 1.7 * 0.36] * 2 + [0.0001 * 1.7], rel=1e-5)
    assert "<!--mass=1.7 - length=0.6-->" in path.read_text()  # "--" is not allowed inside an XML comment


# Ant and Humanoid infer inertia from geoms (inertiafromgeom="true"), FrankaCabinet randomizes actuator gains with
# their biasprm, ShadowHand frictions, mjcf is a model from the YAML alone
@pytest.mark.parametrize("name", ["Cartpole", "Ant", "Humanoid", "FrankaCabinet", "ShadowHand", "mjcf"])
def test_an_exported_mjcf_compiles_to_the_model_the_simulators_use(compose, tmp_path, name):
    task = registry.build("task", compose([f"task={name}"]).task)
    values = np.random.default_rng(0).uniform(task.spec.low, task.spec.high)
    want = model_with_params(task, values)
    got = mujoco.MjModel.from_xml_path(str(write_mjcf(task, values, tmp_path / "m.xml")))
    for field in task.spec.fields:
        assert not np.allclose(_field(want, field), _field(task.model, field)), field  # the values moved it
        np.testing.assert_allclose(_field(got, field), _field(want, field), rtol=1e-5, atol=1e-9, err_msg=field)
    nominal = mujoco.MjModel.from_xml_string(mjcf_with_params(task, task.spec.nominal))
    for field in ("body_mass", "body_inertia", "body_ipos", "geom_size", "dof_damping", "actuator_gainprm"):
        np.testing.assert_allclose(_field(nominal, field), _field(task.model, field), rtol=1e-5, atol=1e-9)


def test_quantiles_are_exact_for_priors_and_from_the_moment_draws_otherwise():
    box = BoxUniform(torch.tensor([0.0, 1.0], dtype=F64), torch.tensor([1.0, 3.0], dtype=F64))
    torch.testing.assert_close(box.quantiles(), torch.tensor([[0.05, 1.1], [0.5, 2.0], [0.95, 2.9]], dtype=F64))
    gauss = GaussianPrior(torch.tensor([0.0], dtype=F64), torch.tensor([2.0], dtype=F64))
    torch.testing.assert_close(gauss.quantiles((0.975,)), torch.tensor([[2 * 1.959964]], dtype=F64), atol=1e-5, rtol=0)
    mixture = GaussianMixture(torch.zeros(1), torch.tensor([[0.0, 10.0]], dtype=F64),
                              torch.diag(torch.tensor([4.0, 0.01], dtype=F64))[None])
    q = mixture.quantiles()  # 20,000 draws: a quantile's standard error is about 0.01 sd
    torch.testing.assert_close(q, torch.tensor([[-3.29, 9.8355], [0.0, 10.0], [3.29, 10.1645]], dtype=F64),
                               atol=0.06, rtol=0)
    torch.testing.assert_close(mixture.quantiles(), q)  # the same draws every time
    torch.testing.assert_close(mixture.quantiles((0.5, 0.95)), q[1:])
    with pytest.raises(ValueError, match="levels must lie in"):
        mixture.quantiles((5, 50))


def _posterior():
    gaussian = GaussianMixture(torch.zeros(1), torch.tensor([[1.0, 0.5]], dtype=F64),
                               torch.tensor([[[0.04, 0.01], [0.01, 0.01]]], dtype=F64))
    return TruncatedMixture(gaussian, torch.tensor([0.5, 0.25], dtype=F64), torch.tensor([2.0, 1.0], dtype=F64))


def test_the_torch_view_has_torchs_shapes_support_and_seeding():
    dist = _posterior()
    view = TorchDistribution(dist, ["mass", "length"])
    assert isinstance(view, torch.distributions.Distribution)
    assert view.event_shape == (2,) and view.batch_shape == ()
    assert view.sample().shape == (2,) and view.sample((3,)).shape == (3, 2) and view.sample((4, 3)).shape == (4, 3, 2)
    assert view.sample((0,)).shape == (0, 2) and view.sample().dtype == torch.float32
    torch.manual_seed(3)
    first = view.sample((5,))
    torch.manual_seed(3)
    torch.testing.assert_close(view.sample((5,)), first)
    inside = torch.tensor([[1.0, 0.5], [1.9, 0.3]])
    torch.testing.assert_close(view.log_prob(inside), dist.log_prob(inside.double()).float())
    assert view.log_prob(inside[None]).shape == (1, 2)
    assert view.support.check(inside).all() and not view.support.check(torch.tensor([2.5, 0.5]))
    assert view.log_prob(torch.tensor([2.5, 0.5])) == -float("inf")
    with pytest.raises(ValueError):  # validate_args: outside the support is an error, as for torch's own
        TorchDistribution(dist, validate_args=True).log_prob(torch.tensor([2.5, 0.5]))
    torch.testing.assert_close(view.mean, dist.mean.float())
    assert TorchDistribution(GaussianPrior(torch.zeros(2), torch.ones(2))).support.check(torch.tensor([1e6, -1e6]))


def test_sbi_takes_the_view_as_a_prior_without_wrapping_or_warnings():
    user_input_checks = pytest.importorskip("sbi.utils.user_input_checks", reason="sbi: pip install '.[sbi]'")
    view = TorchDistribution(_posterior(), ["mass", "length"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prior, dim, returns_numpy = user_input_checks.process_prior(view)
    assert prior is view and dim == 2 and not returns_numpy


def _fake_run(tmp_path, records, rounds=3):
    """A run dir as far as its results.json and config.yaml go (no artifacts: nothing here reads them)."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "config.yaml").write_text(f"rounds: {rounds}\n")
    (tmp_path / "results.json").write_text(json.dumps({"task": "Pendulum", "param_names": ["mass", "length"],
                                                       "rounds": records}))
    return tmp_path


def test_a_run_says_which_rounds_distribution_each_round_handed_on(tmp_path):
    def guard(said):
        return {"guard": {"handed_on": said}}

    run = load_run(_fake_run(tmp_path, [{"round": 1, **guard("the prior")}, {"round": 2, **guard("round 2's posterior")},
                                        {"round": 3, **guard("round 2's posterior")}]))
    assert [(h.source, h.is_prior) for h in map(run.handed_on, (1, 2, 3))] == [(0, True), (2, False), (2, False)]
    assert run.handed_on().round == 3 and run.handed_on().description == "round 2's posterior"
    sysid = Run(tmp_path, {"rounds": [{"round": 1, "sysid": {"failed": True}}, {"round": 2, "sysid": {"failed": False}}]},
                None)
    assert [sysid.handed_on(r).source for r in (1, 2)] == [0, 2]
    for wrong in (0, 4):
        with pytest.raises(ValueError, match=f"round_index={wrong}: this run finished rounds 1 to 3"):
            run.handed_on(wrong)
    with pytest.raises(ValueError, match="no round has finished yet"):
        Run(tmp_path, {"rounds": []}, None).handed_on()


@pytest.mark.parametrize(("case", "args", "message"), [
    ("missing", [], "no such run dir"),
    ("no results", [], "no round of this run has finished yet"),
    ("unfinished", [], "finished 1 of its 3 rounds (still running, stopped or killed): resume it, or name a finished "
                       "round with --round"),
    ("finished", ["--round", "2"], "round_index=2: this run finished rounds 1 to 1"),
    ("finished", ["--mjcf", "draw:10", "--samples", "10"], "--mjcf draw:10: there are 10 draws (rows 0 to 9)"),
    ("finished", ["--mjcf", "mode"], "--mjcf mode: write mean, median or draw:K"),
    ("finished", ["--dr-interval", "1.5"], "--dr-interval must lie in (0, 1], got 1.5"),
])
def test_the_export_command_refuses_bad_input_in_one_line_before_any_compute(tmp_path, capsys, monkeypatch, case,
                                                                            args, message):
    monkeypatch.setattr(Run, "posterior", lambda *a, **k: pytest.fail("read a posterior"))
    monkeypatch.setattr(registry, "build", lambda *a, **k: pytest.fail("built a component"))
    run_dir = tmp_path / "run"
    if case == "no results":
        run_dir.mkdir()
        (run_dir / "config.yaml").write_text("rounds: 3\n")
    elif case != "missing":
        _fake_run(run_dir, [{"round": 1, "guard": {"handed_on": "the prior"}}], rounds=3 if case == "unfinished" else 1)
    assert export_main([str(run_dir), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not (run_dir / "export").exists()


"""python -m bayessim_exp.export on a finished run: samples, quantiles, the DR YAML and the MJCF hold what each round
handed on (round 1: the prior, its guard failing; round 2: its own posterior), the MJCF loads in MuJoCo with the
posterior mean in the fields the task's spec names, and sbi and ArviZ take the exported objects."""

import csv
import subprocess
import sys
import warnings

import mujoco
import numpy as np
import pytest
import torch
import yaml

from bayessim_exp import api, registry
from bayessim_exp.diagnostics import guard
from bayessim_exp.export import main as export_main
from bayessim_exp.pipeline import Pipeline

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("test_export")]  # one worker: one run for the module

SMOKE = ["task=Pendulum", "debug=smoke", "logging.progress=false"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A Pendulum smoke run whose round 1 hands on the prior (its guard forced to fail) and round 2 its own
    posterior."""
    out = tmp_path_factory.mktemp("run")
    verdicts = iter([guard.GuardReport(["overconfident: forced"], True), guard.GuardReport([])])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("bayessim_exp.inference.bayessim.method.check_posterior", lambda *a, **k: next(verdicts))
        results = Pipeline(api.compose(SMOKE), out).run()
    assert [r["guard"]["handed_on"] for r in results["rounds"]] == ["the prior", "round 2's posterior"]
    return out


@pytest.fixture(scope="module")
def exported(run_dir):
    """The default export (the last round) with 500 draws and the MJCF of the mean and of draw 7."""
    assert export_main([str(run_dir), "--samples", "500", "--mjcf", "mean", "--mjcf", "draw:7"]) == 0
    return run_dir / "export" / "round_002"


def _csv(path):
    with path.open() as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def test_the_export_writes_named_samples_of_what_the_last_round_handed_on(run_dir, exported):
    run = api.load_run(run_dir)
    header, rows = _csv(exported / "samples.csv")
    assert header == ["mass", "length"] and len(rows) == 500
    want = run.samples(500).values  # seed 0, as the command's default
    np.testing.assert_array_equal(np.array(rows, dtype=float), want.numpy())
    torch.testing.assert_close(want, run.posterior(2).sample((500,), generator=torch.Generator().manual_seed(0)))
    npz = np.load(exported / "samples.npz")
    np.testing.assert_array_equal(npz["samples"], want.numpy())
    assert list(npz["names"]) == ["mass", "length"] and npz["round"] == 2 and npz["handed_on_round"] == 2
    assert not npz["prior"] and str(npz["task"]) == "Pendulum"


def test_results_json_and_the_export_give_the_5_50_95_quantiles_of_what_was_handed_on(run_dir, exported):
    run = api.load_run(run_dir)
    box = run.prior  # round 1 handed on the uniform prior: its quantiles exactly
    first = run.results["rounds"][0]["posterior_quantiles"]
    for key, level in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
        want = box.low + level * (box.high - box.low)
        assert list(first[key].values()) == pytest.approx(want.tolist(), rel=1e-12)
    second = run.results["rounds"][1]["posterior_quantiles"]
    q = run.posterior(2).quantiles()
    np.testing.assert_allclose([list(second[k].values()) for k in ("q05", "q50", "q95")], q.numpy(), rtol=1e-9)
    assert (q[0] < q[1]).all() and (q[1] < q[2]).all()
    header, rows = _csv(exported / "quantiles.csv")
    assert header == ["parameter", "mean", "std", "q05", "q50", "q95", "low", "high"]
    table = {row[0]: [float(v) for v in row[1:]] for row in rows}
    mean = run.results["rounds"][1]["posterior_mean"]
    for j, name in enumerate(["mass", "length"]):
        assert table[name][0] == pytest.approx(mean[name], rel=1e-9)
        assert table[name][2:5] == pytest.approx(q[:, j].tolist(), rel=1e-9)
        assert table[name][5:] == pytest.approx([float(box.low[j]), float(box.high[j])])


def test_the_mjcf_loads_in_mujoco_with_the_posterior_mean_in_the_specs_fields(run_dir, exported):
    mean = api.load_run(run_dir).results["rounds"][1]["posterior_mean"]
    model = mujoco.MjModel.from_xml_path(str(exported / "Pendulum_mean.xml"))
    pole = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "pole")
    rod = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "rod")
    # conf/task/Pendulum.yaml: mass and length scale the MJCF's 1 kg and 1 m (a rod of half-length 0.5)
    assert model.body_mass[pole] == pytest.approx(mean["mass"], rel=1e-5)
    assert model.geom_size[rod, 1] == pytest.approx(0.5 * mean["length"], rel=1e-5)
    assert model.body_ipos[pole, 2] == pytest.approx(0.5 * mean["length"], rel=1e-5)
    text = (exported / "Pendulum_mean.xml").read_text()
    assert "round 2's posterior, not the prior" in text
    _, rows = _csv(exported / "samples.csv")
    draw = mujoco.MjModel.from_xml_path(str(exported / "Pendulum_draw7.xml"))
    assert draw.body_mass[pole] == pytest.approx(float(rows[7][0]), rel=1e-5)
    assert draw.geom_size[rod, 1] == pytest.approx(0.5 * float(rows[7][1]), rel=1e-5)


def test_the_dr_yaml_feeds_back_as_the_tasks_own_parameters(run_dir, exported):
    run = api.load_run(run_dir)
    dr = yaml.safe_load((exported / "dr.yaml").read_text())
    assert dr["source"] == {"run_dir": str(run_dir), "method": "bayessim", "round": 2,
                            "handed_on": "round 2's posterior", "handed_on_round": 2, "prior": False}
    declared = run.config.task.parameters
    q = run.posterior(2).quantiles((0.005, 0.995))
    for j, name in enumerate(["mass", "length"]):
        entry = dr["parameters"][name]
        assert entry["operation"] == declared[name].operation and entry["targets"] == list(declared[name].targets)
        want = [max(float(q[0, j]), run.task.spec.low[j]), min(float(q[1, j]), run.task.spec.high[j])]
        assert entry["range"] == pytest.approx(want, rel=1e-5)
        marginal = dr["marginals"][name]
        assert marginal["mean"] == pytest.approx(run.results["rounds"][1]["posterior_mean"][name], rel=1e-5)
        assert marginal["q05"] < marginal["q50"] < marginal["q95"]
    task = registry.build("task", api.compose(["task=Pendulum", *dr["overrides"]]).task)  # the overrides compose
    np.testing.assert_allclose(np.stack([task.spec.low, task.spec.high], 1),
                               [dr["parameters"][n]["range"] for n in ["mass", "length"]])
    assert dr["samples"] == {"file": "samples.csv", "draws": 500, "seed": 0}
    assert np.asarray(dr["correlation"]).shape == (2, 2)


def test_an_earlier_round_exports_the_prior_it_handed_on(run_dir, tmp_path):
    assert export_main([str(run_dir), "--round", "1", "--samples", "50", "--out", str(tmp_path)]) == 0
    run = api.load_run(run_dir)
    npz = np.load(tmp_path / "samples.npz")
    assert npz["round"] == 1 and npz["handed_on_round"] == 0 and npz["prior"]
    np.testing.assert_array_equal(npz["samples"], run.prior.sample((50,), generator=torch.Generator().manual_seed(0)))
    dr = yaml.safe_load((tmp_path / "dr.yaml").read_text())
    assert dr["source"]["prior"] and dr["source"]["handed_on"] == "the prior"
    assert [dr["parameters"][n]["range"] for n in ["mass", "length"]] == [[0.5, 2.0], [0.25, 1.0]]
    assert "handed on (the prior) written in" in (tmp_path / "Pendulum_mean.xml").read_text()


def test_sbi_takes_the_torch_view_as_a_prior_and_pairplots_the_samples(run_dir, exported):
    pytest.importorskip("sbi", reason="sbi is an optional extra: pip install 'bayessim_exp[sbi]'")
    import matplotlib

    matplotlib.use("Agg")
    from sbi.analysis import pairplot
    from sbi.utils.user_input_checks import process_prior

    run = api.load_run(run_dir)
    view = run.torch_distribution()
    samples = run.samples(200)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prior, dim, _ = process_prior(view)
        assert prior is view and dim == 2  # taken as it is: no wrapper, no warning
        # sbi 0.27's pairplot itself warns under NumPy 2 whatever it is given (a plain ndarray too)
        warnings.filterwarnings("ignore", "__array__ implementation doesn't accept a copy keyword", DeprecationWarning)
        for given in (samples.values, np.load(exported / "samples.npz")["samples"]):
            pairplot(given, labels=samples.names, limits=[[0.5, 2.0], [0.25, 1.0]])


def test_to_arviz_holds_the_samples_by_name(run_dir):
    pytest.importorskip("arviz", reason="ArviZ is an optional extra: pip install 'bayessim_exp[arviz]'")
    run = api.load_run(run_dir)
    data = run.to_arviz(100, round_index=1)
    assert set(data.posterior.data_vars) == {"mass", "length"} and data.posterior["mass"].shape == (1, 100)
    np.testing.assert_array_equal(data.posterior["length"].values[0], run.samples(100, 1)["length"].numpy())
    assert data.attrs["handed_on"] == "the prior" and data.attrs["round"] == 1 and data.attrs["prior"] == 1


def test_the_command_runs_as_a_module_and_prints_its_table(run_dir, tmp_path):
    out = subprocess.run([sys.executable, "-m", "bayessim_exp.export", str(run_dir), "--samples", "20",
                          "--out", str(tmp_path)], capture_output=True, text=True, check=True)
    assert "Pendulum, round 2 of" in out.stdout and "handed on round 2's posterior" in out.stdout
    mean = api.load_run(run_dir).results["rounds"][1]["posterior_mean"]
    assert f"{mean['mass']:.5g}" in out.stdout.split("\nmass")[1].split("\n")[0]

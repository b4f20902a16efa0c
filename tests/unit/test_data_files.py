"""Posteriors, fitted models and run artifacts are data files (data_files.py): every allowed class comes back
unchanged, and a file that would run code, names an unknown class or was altered is refused before it runs."""

import json
import os
from pathlib import Path

import pytest
import torch

from bayessim_exp import api
from bayessim_exp.artifacts import RunDir
from bayessim_exp.data_files import FORMAT, allowed_classes, dumps, load_state, save_state
from bayessim_exp.distributions.base import ParameterDistribution
from bayessim_exp.distributions.importance import DefensiveMixture, ImportancePosterior
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior, LogUniform
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
from bayessim_exp.distributions.restricted import Restricted
from bayessim_exp.distributions.truncated_prior import TruncatedPrior
from bayessim_exp.errors import DataFileError
from bayessim_exp.inference.bayessim.correction import CorrectedProduct

LOW, HIGH = torch.tensor([0.5, -1.0]), torch.tensor([2.0, 1.0])
BOX = BoxUniform(LOW, HIGH)
POINTS = torch.tensor([[1.0, 0.0], [1.5, 0.5], [0.6, -0.9], [3.0, 0.0]], dtype=torch.float64)


def mixture(shift=0.0):
    covs = torch.tensor([[[0.04, 0.01], [0.01, 0.09]], [[0.09, 0.0], [0.0, 0.04]]], dtype=torch.float64)
    return GaussianMixture(torch.tensor([0.3, -0.2]), torch.tensor([[1.0, 0.0], [1.5, 0.5]]) + shift, covs)


def fitted(name, probit=False):
    g = torch.Generator().manual_seed(0)
    theta = LOW + (HIGH - LOW) * torch.rand(300, 2, generator=g)
    x = torch.cat([theta, theta.sum(1, keepdim=True)], 1) + 0.05 * torch.randn(300, 3, generator=g)
    small = {} if name == "linear" else {"hidden": [8], "max_epochs": 2, "batch_size": 64}
    return api.fit_posterior_model(name, theta, x, prior=BOX, probit=probit, **small)


X_OBS = torch.tensor([1.2, 0.3, 1.5])

# one instance per allowed class (the test below fails for a class added without one)
BUILDERS = {
    "BoxUniform": lambda: BOX,
    "LogUniform": lambda: LogUniform(LOW.abs() + 0.1, HIGH + 2.0),
    "GaussianPrior": lambda: GaussianPrior(torch.tensor([1.0, 0.0]), torch.tensor([0.5, 0.4]), LOW, HIGH),
    "GaussianMixture": mixture,
    "TruncatedMixture": lambda: TruncatedMixture(mixture(), LOW, HIGH, num_mc=4000),
    "ProbitTransform": lambda: ProbitTransform(BOX),
    "ProbitPosterior": lambda: ProbitPosterior(mixture(-1.0), ProbitTransform(BOX)),
    "Restricted": lambda: Restricted(mixture(), LOW, HIGH, num_mc=4000),
    "TruncatedPrior": lambda: TruncatedPrior(BOX, TruncatedMixture(mixture(), LOW, HIGH, num_mc=4000), num=4000),
    "DefensiveMixture": lambda: DefensiveMixture([mixture(), BOX]),
    "ImportancePosterior": lambda: ImportancePosterior(CorrectedProduct([mixture()], BOX, 1.0, [], 1.0),
                                                       DefensiveMixture([mixture(), BOX]), num=4000),
    "CorrectedProduct": lambda: CorrectedProduct([mixture(), mixture(0.1)], BOX, -1.0, [BOX], 0.5),
    "MDNN": lambda: fitted("mdnn").model,
    "MDRFF": lambda: fitted("mdrff").model,
    "Flow": lambda: fitted("flow").model,
    "LinearGaussian": lambda: fitted("linear").model,
    "MdnnConfig": lambda: fitted("mdnn").model.cfg,
    "MdrffConfig": lambda: fitted("mdrff").model.cfg,
    "FlowConfig": lambda: fitted("flow").model.cfg,
    "LinearConfig": lambda: fitted("linear").model.cfg,
    "FlowConditional": lambda: fitted("flow").model.conditional(X_OBS),
    "FittedPosterior": lambda: fitted("mdnn", probit=True),
}


def test_every_allowed_class_has_a_round_trip_test():
    assert set(BUILDERS) == set(allowed_classes())


def same_outputs(a, b):
    """What each kind of object computes, evaluated on `a` and its reloaded copy `b`."""
    if isinstance(a, ParameterDistribution):
        g = lambda: torch.Generator().manual_seed(7)  # noqa: E731
        assert torch.equal(a.log_prob(POINTS), b.log_prob(POINTS))
        assert torch.equal(a.sample((64,), generator=g()), b.sample((64,), generator=g()))
        # without a generator: torch's global one, or the distribution's own, whose state the file keeps
        draws = []
        for dist in (a, b):
            torch.manual_seed(3)
            draws.append(dist.sample((8,)))
        assert torch.equal(*draws)
    elif isinstance(a, api.FittedPosterior):
        assert torch.equal(a.posterior(X_OBS).log_prob(POINTS), b.posterior(X_OBS).log_prob(POINTS))
        assert a.history == b.history and a.config == b.config
    elif isinstance(a, ProbitTransform):
        assert torch.equal(a.to_probit(POINTS), b.to_probit(POINTS))
    elif isinstance(a, CorrectedProduct):
        assert torch.equal(a(POINTS), b(POINTS))
    elif hasattr(a, "conditional"):
        assert torch.equal(a.conditional(X_OBS).log_prob(POINTS), b.conditional(X_OBS).log_prob(POINTS))
        assert a.cfg == b.cfg
    else:
        assert a == b


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_round_trip(name, tmp_path):
    torch.manual_seed(0)
    obj = BUILDERS[name]()
    assert type(obj).__name__ == name
    save_state(obj, tmp_path / "obj.pt")
    torch.load(tmp_path / "obj.pt", weights_only=True)  # plain tensors and containers
    same_outputs(obj, load_state(tmp_path / "obj.pt"))


def test_distribution_and_fitted_posterior_loaders(tmp_path):
    post = BUILDERS["ProbitPosterior"]()
    post.save(tmp_path / "post.pt")
    same_outputs(post, ParameterDistribution.load(tmp_path / "post.pt"))
    fit = BUILDERS["FittedPosterior"]()
    fit.save(tmp_path / "fit.pt")
    same_outputs(fit, api.FittedPosterior.load(tmp_path / "fit.pt"))
    with pytest.raises(DataFileError, match="not a FittedPosterior"):
        api.FittedPosterior.load(tmp_path / "post.pt")


class RunsCode:
    """Unpickling it runs a shell command that creates `marker`."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_a_pickle_that_runs_code_is_refused(tmp_path):
    marker, evil = tmp_path / "marker", tmp_path / "evil.pt"
    torch.save({"state": RunsCode(marker)}, evil)
    with pytest.raises(DataFileError, match="could run any code"):
        api.FittedPosterior.load(evil)
    with pytest.raises(DataFileError, match="could run any code"):
        ParameterDistribution.load(evil)
    assert not marker.exists()
    torch.load(evil, weights_only=False)  # the file is what it says: unpickled, it runs
    assert marker.exists()


def test_a_run_dir_holding_code_is_refused(tmp_path):
    run, marker = tmp_path / "run", tmp_path / "marker"
    cfg = api.compose(["task=Pendulum", "debug=smoke"])
    RunDir(run).bind_config(cfg)
    (run / "results.json").write_text(json.dumps({"rounds": [{"round": 1}]}))
    for stage in ("real", "collect", "summarize", "identifiability", "fit", "condition", "model_check", "guard"):
        (run / "round_001").mkdir(exist_ok=True)
        torch.save({"posterior": RunsCode(marker)}, run / "round_001" / f"{stage}.pt")
    loaded = api.load_run(run)
    with pytest.raises(DataFileError, match="trusted=True"):
        loaded.posterior()
    assert not marker.exists()


def test_an_unknown_or_altered_file_is_refused(tmp_path):
    raw = torch.load(_bytes_file(tmp_path, dumps(BOX)), weights_only=True)
    description = json.loads(raw["description"])
    description["value"]["$class"] = "Popen"
    path = tmp_path / "unknown.pt"
    torch.save({**raw, "description": json.dumps(description)}, path)
    with pytest.raises(DataFileError, match="class 'Popen', which is not one a data file may hold"):
        ParameterDistribution.load(path)
    torch.save({**raw, "tensors": {**raw["tensors"], "t0": torch.zeros(5)}}, path)  # low of another shape
    with pytest.raises(DataFileError, match="altered"):
        ParameterDistribution.load(path)
    torch.save({"format": "something else", "tensors": {}}, path)
    with pytest.raises(DataFileError, match=f"not a bayessim_exp data file \\({FORMAT}\\)"):
        ParameterDistribution.load(path)


def _bytes_file(tmp_path, data: bytes) -> Path:
    path = tmp_path / "data.pt"
    path.write_bytes(data)
    return path


def test_old_pickled_files_load_when_trusted_and_convert(tmp_path):
    path = tmp_path / "old.pt"
    post = BUILDERS["TruncatedMixture"]()
    torch.save(post, path)  # how distributions were saved before the data format
    with pytest.raises(DataFileError, match=r"ParameterDistribution.load\(.*, trusted=True\).save"):
        ParameterDistribution.load(path)
    ParameterDistribution.load(path, trusted=True).save(path)
    same_outputs(post, ParameterDistribution.load(path))

    fit = fitted("mdnn")
    torch.save({"name": fit.name, "config": fit.config, "state": fit.model.state_dict(), "history": fit.history,
                "theta_dim": 2, "x_dim": 3, "prior": fit.prior, "probit": False}, path)  # the old FittedPosterior file
    with pytest.raises(DataFileError, match=r"api.FittedPosterior.load\(.*, trusted=True\).save"):
        api.FittedPosterior.load(path)
    api.FittedPosterior.load(path, trusted=True).save(path)
    same_outputs(fit, api.FittedPosterior.load(path))


def test_an_old_run_dir_converts_when_trusted(tmp_path):
    run_dir = RunDir(tmp_path)
    artifact = {"posterior": BUILDERS["GaussianMixture"](), "seconds": 1.0}
    run_dir.stage_file(1, "condition").parent.mkdir()
    torch.save(artifact, run_dir.stage_file(1, "condition"))  # how artifacts were written before
    with pytest.raises(DataFileError, match=r"api.load_run\(.*, trusted=True\)"):
        run_dir.load(1, "condition")
    (tmp_path / "results.json").write_text("{}")
    (tmp_path / "config.yaml").write_text("{}")
    api.load_run(tmp_path, trusted=True)
    same_outputs(artifact["posterior"], run_dir.load(1, "condition")["posterior"])

"""The public Python API: fit a posterior model without Hydra, run the pipeline, read runs back.

    from bayessim_exp import api
    fitted = api.fit_posterior_model("mdnn", theta, x, prior=api.BoxUniform(low, high), components=3)
    post = fitted.posterior(x_obs)          # [F] or several observations [n, F]
    post.sample((1000,)); post.log_prob(theta)
    results = api.run(["task=Pendulum", "debug=smoke"], out_dir="outputs/try")
    run = api.load_run("outputs/try"); run.posterior(round_index=2)
    run.samples(1000).values; run.torch_distribution(); run.to_arviz()   # what the run handed on, exported
"""

from __future__ import annotations

import dataclasses
import functools
import json
import re
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from . import registry
from .artifacts import RunDir
from .data_files import data_class, load_state, save_state
from .distributions.base import ParameterDistribution
from .distributions.convert import as_parameter_distribution
from .distributions.independent import BoxUniform, GaussianPrior, LogUniform
from .distributions.probit import ProbitTransform
from .distributions.torch_view import TorchDistribution
from .errors import DataFileError
from .inference.bayessim.condition import condition
from .inference.bayessim.correction import MAX_COMPONENTS
from .logging.tensorboard import NO_TENSORBOARD
from .run_config import check_run_config
from .stages import RoundContext

__all__ = ["BoxUniform", "GaussianPrior", "LogUniform", "FittedPosterior", "fit_posterior_model", "run", "load_run",
           "compose", "Run", "HandedOn", "ParameterSamples", "TorchDistribution"]

CONF_DIR = registry.CONF_DIR


@data_class
@dataclasses.dataclass
class FittedPosterior:
    name: str
    model: Any
    prior: Any
    config: dict
    history: dict
    max_components: int = MAX_COMPONENTS
    probit: ProbitTransform | None = None  # set when the model was fitted in probit space

    def posterior(self, x_obs: torch.Tensor, proposal=None, combination: str = "dispersion"):
        """The posterior given one summary [F] or several i.i.d. ones [n, F]; `proposal`: what the
        training parameters were drawn from, if not the prior (SNPE-A correction; what a prior may be);
        `combination`: how several summaries are combined (inference/bayessim/combination.py)."""
        return condition(self.model, torch.as_tensor(x_obs), self.prior, self.max_components,
                         proposal=as_parameter_distribution(proposal, "proposal"), probit=self.probit,
                         combination=combination)[0]

    def save(self, path: str | Path) -> None:
        """A data file (data_files.py): tensors and a JSON description, nothing that runs when loaded."""
        save_state(self, path)

    @classmethod
    def load(cls, path: str | Path, trusted: bool = False) -> FittedPosterior:
        """trusted=True also reads a file in the old pickle format, running any code it holds;
        `FittedPosterior.load(path, trusted=True).save(path)` converts it."""
        d = load_state(path, trusted, convert_hint=f"bayessim_exp.api.FittedPosterior.load({str(path)!r}, "
                                                   f"trusted=True).save({str(path)!r})")
        if isinstance(d, dict) and "state" in d:  # the old format (trusted=True): the model's state dict
            model = registry.build("model", {**d["config"], "name": d["name"]},
                                   theta_dim=d["theta_dim"], x_dim=d["x_dim"])
            model.load_state_dict(d["state"])
            probit = ProbitTransform(d["prior"]) if d.get("probit") else None
            d = cls(d["name"], model, d["prior"], d["config"], d["history"], probit=probit)
        if not isinstance(d, FittedPosterior):
            raise DataFileError(f"{path} holds a {type(d).__name__}, not a FittedPosterior")
        return d


def fit_posterior_model(name: str, theta: torch.Tensor, x: torch.Tensor, prior=None, seed: int = 0,
                        probit: bool = False, **cfg: Any) -> FittedPosterior:
    """Fit model `name` (mdnn, ...) to simulations (theta [N, D], x [N, F]); cfg overrides the defaults in
    conf/model/<name>.yaml. `prior`: api.BoxUniform, api.GaussianPrior, api.LogUniform, None (flat), or torch's
    Independent(Uniform) / Independent(Normal) over [D] parameters (sbi's BoxUniform), converted to ours.

    probit=True fits the model to the parameters mapped onto R^D by the prior's marginal CDFs
    (distributions/probit.py; needs an independent prior on a box); posteriors come back in parameter units.
    """
    prior = as_parameter_distribution(prior)
    theta, x = torch.as_tensor(theta), torch.as_tensor(x)
    if prior is not None and prior.dim != theta.shape[1]:
        raise ValueError(f"the prior is over {prior.dim} parameters, theta has {theta.shape[1]} columns")
    transform = ProbitTransform(prior) if probit else None
    model = registry.build("model", {**cfg, "name": name}, theta_dim=theta.shape[1], x_dim=x.shape[1])
    target = theta if transform is None else transform.to_probit(theta)
    history = model.fit(target, x, seed=seed, label=name)
    return FittedPosterior(name, model, prior, cfg, history, probit=transform)


def compose(overrides: list[str] | None = None):
    """The config the CLI would compose from these overrides."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR.resolve()), version_base="1.3"):
        return hydra_compose(config_name="config", overrides=list(overrides or []))


def run(overrides: list[str] | None = None, out_dir: str | Path | None = None) -> dict:
    """Run the pipeline as `python -m bayessim_exp <overrides>` would; returns results.json's content. Its
    TensorBoard figures are drawn in this process: a spawned drawing process would import the caller's script again,
    and run it again where it has no `if __name__ == "__main__":` guard."""
    from .pipeline import run as run_pipeline

    cfg = compose(overrides)
    if out_dir is None:
        out_dir = Path("outputs") / cfg.run_name / datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    return run_pipeline(cfg, out_dir, drawing_process=False)


@dataclasses.dataclass(frozen=True)
class HandedOn:
    """What finished round `round` handed on to domain randomization: round `source`'s posterior, or the prior
    (source 0) where its guard fell back (or sysid failed)."""

    round: int
    source: int
    description: str  # as results.json says it: "the prior", "round 2's posterior"

    @property
    def is_prior(self) -> bool:
        return self.source == 0


@dataclasses.dataclass
class ParameterSamples:
    """Draws [n, D] of what a round handed on, with the parameters' names (spec order) and where they come from."""

    names: list[str]
    values: torch.Tensor  # float64 [n, D]
    handed_on: HandedOn
    seed: int

    def __getitem__(self, name: str) -> torch.Tensor:
        if name not in self.names:
            raise KeyError(f"no parameter {name!r}; parameters: {', '.join(self.names)}")
        return self.values[:, self.names.index(name)]

    def __len__(self) -> int:
        return self.values.shape[0]

    def as_dict(self) -> dict[str, np.ndarray]:
        """{name: draws [n]}."""
        return {name: self.values[:, j].numpy() for j, name in enumerate(self.names)}


@dataclasses.dataclass
class Run:
    path: Path
    results: dict
    config: DictConfig  # the run's config.yaml

    @property
    def rounds_planned(self) -> int:
        """The rounds the run goes to: `rounds` plus those the method added (results.json; config.yaml's before
        results.json recorded them)."""
        return self.results.get("rounds_planned", self.config.rounds)

    def round_number(self, round_index: int | None = None) -> int:
        """`round_index` checked against the finished rounds; the last one for None."""
        finished = len(self.results["rounds"])
        if finished == 0:
            raise ValueError(f"{self.path}: no round has finished yet")
        r = finished if round_index is None else round_index
        if not isinstance(r, int) or not 1 <= r <= finished:
            raise ValueError(f"round_index={round_index}: this run finished rounds 1 to {finished}")
        return r

    @functools.cached_property
    def _task_and_prior(self):
        rc = check_run_config(self.config)
        registry.load_plugins(rc.plugins)
        task = registry.build("task", self.config.task)
        return task, registry.build("prior", self.config.prior, spec=task.spec)

    @property
    def task(self):
        """The run's task (its model and ParamSpec), built from its config."""
        return self._task_and_prior[0]

    @property
    def prior(self) -> ParameterDistribution:
        return self._task_and_prior[1]

    @property
    def param_names(self) -> list[str]:
        return list(self.results["param_names"])

    def posterior(self, round_index: int | None = None) -> ParameterDistribution:
        """The distribution finished round `round_index` (1, 2, ...; the last round by default) handed on, read by the
        method's reader (registry: posterior) from the round's artifacts and the prior: no simulator, summarizer or
        model is built."""
        r = self.round_number(round_index)
        read = registry.posterior_reader(self.config.method.name)
        return read(RoundContext(RunDir(self.path), r, check_run_config(self.config).seed, NO_TENSORBOARD),
                    self.prior)

    def handed_on(self, round_index: int | None = None) -> HandedOn:
        """Whose distribution round `round_index` handed on, as its record in results.json says."""
        r = self.round_number(round_index)
        record = self.results["rounds"][r - 1]
        if "handed_on" in record:  # the pipeline's record; runs recorded before it: the guard's or sysid's words
            return HandedOn(r, record["handed_on"]["round"], record["handed_on"]["name"])
        guard = record.get("guard")
        said = guard.get("handed_on") if isinstance(guard, dict) else None
        if said == "the prior" or (record.get("sysid") or {}).get("failed"):
            return HandedOn(r, 0, "the prior")
        if said and (m := re.fullmatch(r"round (\d+)'s posterior", said)):
            return HandedOn(r, int(m.group(1)), said)
        return HandedOn(r, r, f"round {r}'s posterior")

    def samples(self, n: int = 1000, round_index: int | None = None, seed: int = 0) -> ParameterSamples:
        """n draws of what round `round_index` (the last by default) handed on, named; the same for the same seed."""
        handed = self.handed_on(round_index)
        draws = self.posterior(handed.round).sample((n,), generator=torch.Generator().manual_seed(seed)).double()
        return ParameterSamples(self.param_names, draws, handed, seed)

    def torch_distribution(self, round_index: int | None = None, dtype: torch.dtype = torch.float32) -> TorchDistribution:
        """What round `round_index` handed on as a torch.distributions.Distribution (distributions/torch_view.py):
        event_shape [D], support the prior's box, sample and log_prob in `dtype`; sbi's process_prior takes it as is."""
        return TorchDistribution(self.posterior(round_index), self.param_names, dtype)

    def to_arviz(self, n: int = 1000, round_index: int | None = None, seed: int = 0):
        """Run.samples as an ArviZ InferenceData (one chain of n draws, a variable per parameter; attrs say which
        round's distribution it is); needs ArviZ (pip install 'bayessim_exp[arviz]')."""
        try:
            import arviz
        except ImportError:
            raise ImportError("Run.to_arviz needs ArviZ: pip install 'bayessim_exp[arviz]'") from None
        s = self.samples(n, round_index, seed)
        return arviz.from_dict(posterior={k: v[None] for k, v in s.as_dict().items()},
                               attrs={"run_dir": str(self.path), "round": s.handed_on.round,
                                      "handed_on": s.handed_on.description, "prior": int(s.handed_on.is_prior),
                                      "seed": seed})


def load_run(path: str | Path, trusted: bool = False) -> Run:
    """The run in `path`; its artifacts are read as data files (data_files.py) when a posterior is asked for.
    trusted=True first rewrites artifacts in the old pickle format as data files, running any code they hold."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such run dir")
    if not (path / "config.yaml").is_file():
        raise FileNotFoundError(f"{path} is not a run dir: it has no config.yaml")
    if not (path / "results.json").is_file():
        raise FileNotFoundError(f"{path}: no round of this run has finished yet (no results.json)")
    if trusted:
        RunDir(path).convert()
    results = json.loads((path / "results.json").read_text())
    return Run(path, results, OmegaConf.load(path / "config.yaml"))

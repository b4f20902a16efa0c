"""The public Python API: fit a posterior model without Hydra, run the pipeline, read runs back.

    from bayessim_exp import api
    fitted = api.fit_posterior_model("mdnn", theta, x, prior=api.BoxUniform(low, high), components=3)
    post = fitted.posterior(x_obs)          # [F] or several observations [n, F]
    post.sample((1000,)); post.log_prob(theta)
    results = api.run(["task=Pendulum", "debug=smoke"], out_dir="outputs/try")
    run = api.load_run("outputs/try"); run.posterior(round_index=2)
"""

from __future__ import annotations

import dataclasses
import json
from datetime import datetime
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf

from . import registry
from .artifacts import RunDir
from .data_files import data_class, load_state, save_state
from .distributions.base import ParameterDistribution
from .distributions.convert import as_parameter_distribution
from .distributions.independent import BoxUniform, GaussianPrior, LogUniform
from .distributions.probit import ProbitTransform
from .errors import DataFileError
from .inference.bayessim.condition import condition
from .inference.bayessim.correction import MAX_COMPONENTS
from .run_config import check_run_config
from .stages import RoundContext

__all__ = ["BoxUniform", "GaussianPrior", "LogUniform", "FittedPosterior", "fit_posterior_model", "run", "load_run", "compose"]

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


@dataclasses.dataclass
class Run:
    path: Path
    results: dict
    config: DictConfig  # the run's config.yaml

    def posterior(self, round_index: int | None = None) -> ParameterDistribution:
        """The distribution finished round `round_index` (1, 2, ...; the last round by default) handed on, read by the
        method's reader (registry: posterior) from the round's artifacts and the prior: no simulator, summarizer or
        model is built."""
        finished = len(self.results["rounds"])
        r = finished if round_index is None else round_index
        if not 1 <= r <= finished:
            raise ValueError(f"round_index={round_index}: this run finished rounds 1 to {finished}")
        rc = check_run_config(self.config)
        registry.load_plugins(rc.plugins)
        task = registry.build("task", self.config.task)
        prior = registry.build("prior", self.config.prior, spec=task.spec)
        read = registry.posterior_reader(self.config.method.name)
        return read(RoundContext(RunDir(self.path), r, rc.seed, None), prior)


def load_run(path: str | Path, trusted: bool = False) -> Run:
    """The run in `path`; its artifacts are read as data files (data_files.py) when a posterior is asked for.
    trusted=True first rewrites artifacts in the old pickle format as data files, running any code they hold."""
    path = Path(path)
    if trusted:
        RunDir(path).convert()
    results = json.loads((path / "results.json").read_text())
    return Run(path, results, OmegaConf.load(path / "config.yaml"))

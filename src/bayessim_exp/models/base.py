"""What every posterior model offers, and the training loop the mixture-density models share."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Protocol

import numpy as np
import torch

from ..distributions.mixture import GaussianMixture
from ..errors import ConfigError, TrainingError
from .adam_steps import adam_steps


class PosteriorModel(Protocol):
    def fit(self, theta: torch.Tensor, x: torch.Tensor, *, seed: int, label: str = "",
            on_epoch: Callable[[int, float, float], None] | None = None,
            calibration_rows: torch.Tensor | None = None, calibration_only: torch.Tensor | None = None) -> dict:
        """`calibration_rows` ([N] bool): the pairs drawn like those the posterior will be used on (the
        latest round's, when rounds pool simulations from several proposals); models calibrate their
        spread on the validation pairs among them. None: every pair. `calibration_only` ([N] bool): pairs
        simulated as the real data were (replays without the collect policy's noise), never trained on nor
        read by early stopping; where given, the spread is calibrated on those among `calibration_rows`."""

    def conditional(self, x_obs: torch.Tensor) -> GaussianMixture: ...

    def inputs(self, x: torch.Tensor) -> torch.Tensor:
        """What q(theta | x) is a function of, for summaries x [N, F]: [N, E] (standardised summaries, or their
        ridge predictions of the parameters); the guard measures how far the real data's lie from the training
        simulations' (diagnostics/extrapolation.py)."""

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


@dataclasses.dataclass
class TrainConfig:
    """Optimisation settings shared by the mixture-density models."""

    lr: float
    batch_size: int
    max_epochs: int
    patience: int  # epochs without validation improvement before stopping
    val_fraction: float
    weight_decay: float
    project_inputs: bool  # replace the summaries by ridge predictions of the parameters (models/projection.py)
    calibrate: bool  # rescale the fitted posterior's spread per parameter on the validation split (mixtures)

    def validate(self) -> None:
        if self.lr <= 0 or self.batch_size < 1 or self.max_epochs < 1 or self.patience < 1:
            raise ConfigError("lr must be > 0; batch_size, max_epochs, patience >= 1")
        if not 0.0 < self.val_fraction < 0.5:
            raise ConfigError(f"val_fraction must be in (0, 0.5), got {self.val_fraction}")
        if self.weight_decay < 0:
            raise ConfigError("weight_decay must be >= 0")


# a density network's batches are small matrices: past 8 torch threads a 16-core CPU trained none faster
# (docs/benchmarks.md)
CPU_TRAINING_THREADS = 8
_ROUNDING = 1e-6  # a column whose spread is below this share of its size differs by float32 rounding only


def constant_columns(data: torch.Tensor) -> torch.Tensor:
    """[F] bool: the columns of `data` [N, F] that are constant up to float rounding."""
    return data.std(0) <= _ROUNDING * (1 + data.abs().amax(0))


def column_scale(data: torch.Tensor) -> torch.Tensor:
    """Each column's standard deviation over the rows of `data` [N, F], and 1 for a constant column: its
    rounding noise would turn a later real difference (a simulation of the next round, real data) into an
    input of millions."""
    std = data.std(0)
    return torch.where(constant_columns(data), torch.ones_like(std), std)


class Standardizer(torch.nn.Module):
    """Affine map to zero mean and unit variance (column_scale), fitted once and then kept (fine-tuning)."""

    def __init__(self, dim: int):
        super().__init__()
        self.register_buffer("shift", torch.zeros(dim))
        self.register_buffer("scale", torch.ones(dim))

    def fit(self, data: torch.Tensor) -> None:
        self.shift.copy_(data.mean(0))
        self.scale.copy_(column_scale(data))

    def forward(self, data: torch.Tensor) -> torch.Tensor:
        return (data - self.shift) / self.scale


class SavedAsData:
    """A fitted model in a data file (data_files.py): its config, sizes and state dict; rebuilt by its
    constructor, so a model whose network the config does not describe (an `embedding` module given to the
    constructor is code, not data) cannot be saved."""

    def to_state(self) -> dict:
        built = type(self)(self.cfg, self.theta_dim, self.x_dim)
        if repr(getattr(built, "net", None)) != repr(getattr(self, "net", None)):
            raise TypeError(f"this {type(self).__name__}'s network is not the one its config builds (an embedding "
                            "module?): it cannot be saved as data")
        return {"cfg": self.cfg, "theta_dim": self.theta_dim, "x_dim": self.x_dim, "state": self.state_dict()}

    @classmethod
    def from_state(cls, fields: dict):
        model = cls(fields["cfg"], fields["theta_dim"], fields["x_dim"])
        model.load_state_dict(fields["state"])
        return model


class StandardizedDensityModel(SavedAsData):
    """Fitting and state shared by models with standardised inputs and targets.

    Subclasses build `self.net` (a module holding every trainable part and the standardisers
    `self.x_norm`, `self.theta_norm`, and `self.projection` when cfg.project_inputs) and define
    `_nll(theta_std, inputs)` and `conditional`, which reads its inputs through `self.inputs(x)`.
    """

    cfg: TrainConfig
    net: torch.nn.Module
    x_norm: Standardizer
    theta_norm: Standardizer
    fitted: bool = False
    split_seed: int | None = None  # the first fit's seed: the validation split of every later fit (fine-tuning)
    projection = None

    def inputs(self, x: torch.Tensor) -> torch.Tensor:
        """What the network sees: standardised summaries, or their ridge predictions of the parameters."""
        z = self.x_norm(x)
        return z if self.projection is None else self.projection(z)

    def _nll(self, theta_std: torch.Tensor, x_std: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _calibrate(self, theta_std: torch.Tensor, inputs: torch.Tensor, seed: int) -> dict:
        """Fit the spread of q on validation pairs (cfg.calibrate); returns what it found, for the history."""
        raise NotImplementedError

    def fit(self, theta: torch.Tensor, x: torch.Tensor, *, seed: int, label: str = "", on_epoch=None,
            calibration_rows: torch.Tensor | None = None, calibration_only: torch.Tensor | None = None) -> dict:
        """Trains where `x` lives (a GPU when the pipeline runs with device=cuda); the fitted network
        goes back to the CPU, where its state is saved and the posteriors are built. With cfg.calibrate
        the spread is fitted on the validation pairs among `calibration_rows`, or on the `calibration_only` pairs
        among them (PosteriorModel.fit).
        Fine-tuning on rows that extend the previous fit's (rounds pooled in order) keeps their roles in
        the validation split (`validation_split`): early stopping and the calibration never read a pair
        the network was trained on in an earlier round."""
        theta, x = theta.float().to(x.device), x.float()
        self.net.to(x.device)
        inputs = None
        if not self.fitted or self.split_seed is None:  # or a state saved before split seeds were kept
            self.split_seed = seed
        if not self.fitted:  # fine-tuning keeps the first standardisation and projection, so weights stay meaningful
            torch.manual_seed(seed)
            self.net.apply(lambda m: m.reset_parameters() if hasattr(m, "reset_parameters") else None)
            self.x_norm.fit(x)
            self.theta_norm.fit(theta)
            if self.projection is not None:
                inputs = self.projection.fit(self.x_norm(x), self.theta_norm(theta), seed)
        try:
            if inputs is None:
                with torch.no_grad():
                    inputs = self.inputs(x)
            theta_std = self.theta_norm(theta)
            val_idx, train_idx = validation_split(len(theta), self.cfg.val_fraction, self.split_seed, label)
            if calibration_only is not None:  # after the split, so that every other row keeps its role
                only = calibration_only.cpu()
                val_idx, train_idx = val_idx[~only[val_idx]], train_idx[~only[train_idx]]
            history = train_density(self.net, self._nll, theta_std, inputs, val_idx, train_idx, self.cfg,
                                    seed=seed, label=label, on_epoch=on_epoch)
            if self.cfg.calibrate:  # fine-tuning starts from the network's own spread, not the last factors
                self.spread.log_scale.zero_()
                if calibration_only is not None:
                    val_idx = only.nonzero()[:, 0]
                val_idx = calibration_pairs(val_idx, calibration_rows).to(x.device)
                if len(val_idx):
                    history.update(self._calibrate(theta_std[val_idx], inputs[val_idx], seed))
        finally:
            self.net.to("cpu")
        self.fitted = True
        return history

    def state_dict(self) -> dict:
        return {"net": self.net.state_dict(), "fitted": self.fitted, "split_seed": self.split_seed}

    def load_state_dict(self, state: dict) -> None:
        self.net.load_state_dict(state["net"])
        self.fitted, self.split_seed = state["fitted"], state.get("split_seed")  # absent from states saved earlier


def validation_split(n: int, val_fraction: float, seed: int, label: str) -> tuple[torch.Tensor, torch.Tensor]:
    """(validation indices, training indices): row i validates iff the i-th uniform of `seed`'s stream lies
    below val_fraction (at least one row does), so rows keep their role when later fits append rows."""
    draws = torch.from_numpy(np.random.default_rng(seed).random(n))
    validates = draws < val_fraction
    validates[draws.argmin()] = True
    if n - int(validates.sum()) < 2:
        raise TrainingError(f"{label}: {n} simulations are too few to train on")
    return validates.nonzero()[:, 0], (~validates).nonzero()[:, 0]


def calibration_pairs(val_idx: torch.Tensor, calibration_rows: torch.Tensor | None) -> torch.Tensor:
    """The validation indices among `calibration_rows` (all of them when None)."""
    return val_idx if calibration_rows is None else val_idx[calibration_rows.cpu()[val_idx]]


def train_density(
    net: torch.nn.Module,
    nll: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    theta: torch.Tensor,
    x: torch.Tensor,
    val_idx: torch.Tensor,
    train_idx: torch.Tensor,
    cfg: TrainConfig,
    *,
    seed: int,
    label: str,
    on_epoch: Callable[[int, float, float], None] | None = None,
) -> dict:
    """Minimise mean nll(theta_batch, x_batch) over the rows `train_idx` with Adam (in orders shuffled by
    `seed`) and early stopping on the rows `val_idx`.

    Restores the parameters of the best validation epoch. Raises TrainingError naming `label`
    and the step when the loss or a gradient becomes non-finite. On a GPU the optimisation step is
    replayed from a CUDA graph (models/adam_steps.py).
    """
    threads = torch.get_num_threads()
    capped = theta.device.type == "cpu" and threads > CPU_TRAINING_THREADS
    if capped:
        torch.set_num_threads(CPU_TRAINING_THREADS)
    try:
        return _train(net, nll, theta, x, val_idx, train_idx, cfg, seed=seed, label=label, on_epoch=on_epoch)
    finally:
        if capped:
            torch.set_num_threads(threads)


def _train(net, nll, theta, x, val_idx, train_idx, cfg, *, seed, label, on_epoch) -> dict:
    from tqdm.auto import tqdm

    g = torch.Generator().manual_seed(seed)
    val_idx = val_idx.to(theta.device)
    steps = adam_steps(net, nll, theta, x, cfg, label, len(train_idx))
    best, best_state, since_best = math.inf, None, 0
    history: dict[str, list[float]] = {"train": [], "val": []}
    bar = tqdm(range(cfg.max_epochs), desc=f"fit {label}".strip(), leave=False, delay=2, disable=None)
    order = train_idx[torch.randperm(len(train_idx), generator=g)]
    for epoch in bar:
        net.train()
        steps.epoch(order.to(theta.device))
        net.eval()
        val_loss = steps.validation_loss(val_idx)
        order = train_idx[torch.randperm(len(train_idx), generator=g)]  # the next epoch's, while a GPU works
        train_loss, val = steps.finish_epoch(epoch, val_loss)
        if not math.isfinite(val):
            raise TrainingError(f"{label}: validation loss became {val} at epoch {epoch}, step {steps.steps_done}")
        history["train"].append(train_loss)
        history["val"].append(val)
        if on_epoch is not None:
            on_epoch(epoch, train_loss, val)
        bar.set_postfix(train=f"{train_loss:.3f}", val=f"{val:.3f}")
        if val < best - 1e-4:
            best, since_best = val, 0
            best_state = {k: v.detach().clone() for k, v in net.state_dict().items()}
        else:
            since_best += 1
            if since_best >= cfg.patience:
                break
    if best_state is not None:
        net.load_state_dict(best_state)
    history["best_val"] = best
    history["epochs"] = len(history["train"])
    return history

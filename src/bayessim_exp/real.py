"""Where 'real' trajectories come from: a surrogate environment with hidden parameters, or a file.

File format (npz), written by `save_trajectories` or by a robot's logging code:
    states   [n, T+1, S]  float, observations in the task's order (Task.obs_names)
    actions  [n, T, A]    float, normalised to [-1, 1] as the task's actions
    dt       scalar       optional, control timestep in seconds (checked against the task)
    valid    [n, T]       optional bool, False after an episode ended early
    params, param_names   optional, the true parameters if known: used only to score the
                          posterior in results.json, never by the inference
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import logging
import zipfile
from pathlib import Path
from typing import Literal, Protocol

import numpy as np
import torch

from .errors import ConfigError, DataError
from .policies import RandomPolicy, ReplayPolicy
from .sim.pool import SimulatorPool
from .sim.trajectories import Trajectories
from .stages import stage_seed
from .tasks.base import Task

log = logging.getLogger(__name__)


# real.truth=nominal: a nominal truth is kept this far inside the prior (CDF), where a posterior can score it (a
# parameter at its box's face, an additive one at the MJCF's 0, has probit coordinate -7.9); moves are x0.5 or x2
NOMINAL_MARGIN = 0.02
NOMINAL_MOVES = (0.5, 2.0)
# real.truth=corner: every parameter this far (CDF) inside one of its prior's tails, the tail and the depth drawn per
# parameter; seed 0: every parameter 3 % (their middle) above its lower face
CORNER_DEPTHS = (0.01, 0.05)


class RealSource(Protocol):
    """Where a run's 'real' trajectories come from (an option of the `real` config group)."""

    fingerprint: str | None  # a hash of the data outside the config, bound to the run dir (None: nothing)
    true_params: np.ndarray | None  # the true parameters where known: for scoring only, never for inference

    def check(self, horizon: int) -> None:
        """Raise an error now, before any simulation, if the data cannot serve collect.horizon steps."""
        ...

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories | None:
        """This round's new real trajectories (None: none this round)."""
        ...


@dataclasses.dataclass
class SurrogateConfig:
    per_round: int
    # task: the task's real_params | prior: drawn from the prior | nominal: the MJCF's, a few moved | corner: every
    # parameter deep in one of its prior's tails
    truth: Literal["task", "prior", "nominal", "corner"]

    def validate(self) -> None:
        if self.per_round < 1:
            raise ConfigError(f"per_round must be >= 1, got {self.per_round}")


@dataclasses.dataclass
class FileConfig:
    path: str


class SurrogateReal:
    """A simulated 'real' system whose parameters the inference never sees: the task's real_params, or
    (truth=prior) a draw from the prior seeded by the run's seed, so that a sweep over seeds is a
    known-truth calibration study (sweeps/calibration.yaml), or (truth=nominal) what a real robot most likely
    is, the MJCF's own values with a few moved per seed (nominal_truth; sweeps/nominal.yaml). Driven by the
    collect policy, or at random where that policy replays the real trajectories (policy=replay). With
    truth=corner, every parameter in one of its prior's tails (corner_truth; sweeps/corner.yaml)."""

    fingerprint = None  # nothing outside the config to bind to the run dir

    def __init__(self, cfg: SurrogateConfig, task: Task, sims: SimulatorPool, prior, seed: int):
        self.cfg, self.task, self.sims = cfg, task, sims
        generator = torch.Generator().manual_seed(stage_seed(seed, 0, "truth"))
        if cfg.truth == "prior":
            self.true_params: np.ndarray | None = prior.sample((1,), generator=generator)[0].double().numpy()
        elif cfg.truth == "nominal":
            self.true_params = nominal_truth(task, prior, seed, generator)
        elif cfg.truth == "corner":
            self.true_params = corner_truth(prior, seed, generator)
        else:
            self.true_params = task.true_params

    def check(self, horizon: int) -> None:
        """Nothing to check: the task's config was validated when it was built."""

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories:
        if isinstance(policy, ReplayPolicy):
            # a collect policy that replays the real trajectories cannot drive the system it replays: the
            # surrogate acts as a robot under its own excitation controller, uniformly at random
            policy = RandomPolicy(self.task.action_dim, seed)
        params = np.repeat(self.true_params[None], self.cfg.per_round, 0)
        traj = self.sims.get(self.cfg.per_round).rollout(params, policy, horizon, seed)
        if traj.diverged.any():
            raise DataError("the surrogate real system diverged; check the task's real_params")
        return traj


def nominal_truth(task: Task, prior, seed: int, generator: torch.Generator) -> np.ndarray:
    """The task's nominal parameters (the MJCF's values: 0 added for additive ones), kept NOMINAL_MARGIN inside
    the prior's CDF; for seed > 0, 1 to 3 (1 + (seed - 1) % 3) of the parameters with a nonzero nominal value
    moved by a factor of NOMINAL_MOVES each, chosen with `generator`: the real robots a wide prior over many
    multipliers makes atypical (docs/statistics.md, 'Real systems in the prior's tail')."""
    spec = task.spec
    values = torch.as_tensor(spec.nominal, dtype=torch.float64)
    movable = [i for i, p in enumerate(spec.params) if p.operation != "additive" and p.nominal != 0]
    if seed > 0 and movable:
        count = min(len(movable), 1 + (seed - 1) % 3)
        chosen = torch.randperm(len(movable), generator=generator)[:count]
        factors = torch.tensor(NOMINAL_MOVES, dtype=torch.float64)[
            torch.randint(len(NOMINAL_MOVES), (count,), generator=generator)]
        for index, factor in zip(chosen.tolist(), factors.tolist()):
            values[movable[index]] *= factor
    low, high = torch.as_tensor(spec.low, dtype=torch.float64), torch.as_tensor(spec.high, dtype=torch.float64)
    cdf = prior.marginal_cdf(values.clamp(low, high)).clamp(NOMINAL_MARGIN, 1 - NOMINAL_MARGIN)
    return prior.marginal_icdf(cdf).double().numpy()


def corner_truth(prior, seed: int, generator: torch.Generator) -> np.ndarray:
    """A truth in the prior's joint tail: each parameter at a CDF depth in CORNER_DEPTHS from one of
    its tails, tail and depth drawn with `generator` (seed 0: every parameter at the middle depth of its lower tail).
    Each parameter on its own is an ordinary draw (one in ten lies this near a face of its prior); all of them
    together are what a prior-draw study almost never tries (docs/statistics.md, 'Real systems in the prior's tail')."""
    low, high = CORNER_DEPTHS
    dim = prior.dim
    if seed == 0:
        cdf = torch.full((dim,), (low + high) / 2, dtype=torch.float64)
    else:
        depth = low + (high - low) * torch.rand(dim, generator=generator, dtype=torch.float64)
        upper = torch.rand(dim, generator=generator) < 0.5
        cdf = torch.where(upper, 1 - depth, depth)
    return prior.marginal_icdf(cdf).double().numpy()


class FileReal:
    """Trajectories recorded on a real system, all given in the first round.

    The file is read and checked against the task and collect.horizon when the run is built
    (`check`), before any simulation; its SHA-256 (`fingerprint`) binds it to the run dir."""

    def __init__(self, cfg: FileConfig, task: Task):
        if cfg.path in ("???", ""):
            raise ConfigError("real=file needs real.path=<file.npz> (format: README.md, 'Real data from a robot')")
        self.path = Path(cfg.path).expanduser()
        if not self.path.is_file():
            raise ConfigError(f"real.path={cfg.path!r}: no such file")
        self.task = task
        raw = self.path.read_bytes()  # read once: hashed and parsed
        self.fingerprint = hashlib.sha256(raw).hexdigest()
        self._data = read_npz(raw, self.path)
        self.true_params = self._true_params()
        self._trajectories: Trajectories | None = None

    def _true_params(self) -> np.ndarray | None:
        if "params" not in self._data:
            return None
        spec = self.task.spec
        names = [str(n) for n in self._data.get("param_names", spec.names)]
        values = np.asarray(self._data["params"], dtype=float).ravel()
        if len(names) != len(values) or set(names) != set(spec.names):
            log.warning("%s: params are given for %s but task %s infers %s; the posterior is not scored against "
                        "them (name them as the task does in param_names)", self.path, names, self.task.name, spec.names)
            return None
        true = np.array([dict(zip(names, values))[n] for n in spec.names])
        outside = [f"{n}={v:g} not in [{lo:g}, {hi:g}]" for n, v, lo, hi in zip(spec.names, true, spec.low, spec.high)
                   if not lo <= v <= hi]
        if outside:
            log.warning("%s: true parameters outside the prior's box (%s): the posterior has no mass there and its "
                        "log density at them is reported as null; widen the task's ranges to include them",
                        self.path, ", ".join(outside))
        return true

    def check(self, horizon: int) -> None:
        """Validate the file against the task and the horizon (DataError with how to fix it)."""
        self._trajectories = load_trajectories(self._data, self.task, horizon, str(self.path))

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories | None:
        if round_index > 1:
            return None
        if self._trajectories is None:
            raise RuntimeError("FileReal.check(horizon) validates the file and must run before collect")
        return self._trajectories


def read_npz(raw: bytes, path: Path) -> dict[str, np.ndarray]:
    """An npz file's arrays, or one DataError saying what the file is instead (never numpy's advice to load
    it with pickle: a shared file must not run code)."""
    how = "write it with bayessim_exp.real.save_trajectories or numpy.savez"
    if raw.startswith(b"\x93NUMPY"):
        raise DataError(f"{path}: a single .npy array, not an npz archive of named arrays (states, actions, ...); {how}")
    if not raw.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # a zip archive's first bytes
        raise DataError(f"{path}: not an npz file ({len(raw)} bytes, beginning {raw[:8]!r}); {how}")
    data = {}
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as archive:
            for name in archive.files:
                try:
                    data[name] = archive[name]
                except ValueError as exc:
                    if "allow_pickle" not in str(exc):
                        raise
                    raise DataError(f"{path}: array {name!r} holds Python objects (dtype=object), which are not read; "
                                    "save numeric arrays (and param_names as strings)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path}: a damaged npz file ({type(exc).__name__}: {exc}); {how} again") from None
    return data


def _first_non_finite(array: np.ndarray, name: str, columns: list[str]) -> str | None:
    """Where the first NaN or inf of an [n, T, k] array lies, in the file's terms."""
    bad = np.argwhere(~np.isfinite(array))
    if not len(bad):
        return None
    i, t, k = bad[0]
    return (f"{name}[{i}, {t}, {k}] = {array[i, t, k]} (trajectory {i}, step {t}, {columns[k]}; "
            f"{len(bad)} non-finite value(s) in {name})")


def load_trajectories(data: dict, task: Task, horizon: int, where: str) -> Trajectories:
    """Validate recorded arrays against the task and cut them to `horizon` control steps."""
    for key in ("states", "actions"):
        if key not in data:
            raise DataError(f"{where}: missing array {key!r}; found {sorted(data)}")
    states, actions = np.asarray(data["states"], float), np.asarray(data["actions"], float)
    obs = f"[n, T+1, {task.obs_dim}] ({', '.join(task.obs_names)})"
    if states.ndim == 2 and states.shape[1] == task.obs_dim:
        raise DataError(f"{where}: states has shape {states.shape}, one trajectory without its leading axis; "
                        f"states must be {obs}: save states[None] and actions[None]")
    if states.ndim != 3 or states.shape[2] != task.obs_dim:
        raise DataError(f"{where}: states must be {obs} for task {task.name}, got {states.shape}")
    n, t1, _ = states.shape
    if actions.shape != (n, t1 - 1, task.action_dim):
        raise DataError(f"{where}: actions must be [{n}, {t1 - 1}, {task.action_dim}] (one fewer step than states), "
                        f"got {actions.shape}")
    dt = task.cfg.control_dt
    if "dt" not in data:
        log.warning("%s: no dt recorded; assuming the task's control timestep %g s", where, dt)
    elif not np.isclose(float(data["dt"]), dt, rtol=1e-6):
        raise DataError(f"{where}: recorded at dt={float(data['dt']):g} s but task {task.name} runs at {dt:g} s; "
                        f"resample the log to {dt:g} s steps (or set task.control_dt if the model allows it)")
    if t1 - 1 < horizon:
        raise DataError(f"{where}: trajectories have {t1 - 1} steps, fewer than collect.horizon={horizon}; "
                        f"record longer trajectories or run with collect.horizon={t1 - 1} (the summarizer must fit in it)")
    found = (_first_non_finite(states, "states", list(task.obs_names))
             or _first_non_finite(actions, "actions", list(task.action_names)))
    if found:
        raise DataError(f"{where}: {found}; drop or repair those trajectories")
    biggest = np.abs(actions).max(initial=0.0)
    if biggest > 1.0 + 1e-6:
        lo, hi = task.model.actuator_ctrlrange[task.actuators].T  # those the actions drive
        ranges = ", ".join(f"[{a:g}, {b:g}]" for a, b in zip(lo, hi))
        raise DataError(f"{where}: actions must be normalised to [-1, 1], max |a| = {biggest:.3g}; if they are "
                        f"actuator commands (e.g. torque), map each u in its control range ({ranges} for {task.name}) "
                        "to a = (2 u - (high + low)) / (high - low), e.g. divide a symmetric torque by its limit")
    if t1 - 1 > horizon:
        log.warning("%s: trajectories have %d steps; only the first collect.horizon=%d are used", where, t1 - 1, horizon)
    valid = np.asarray(data.get("valid", np.ones((n, t1 - 1), bool)), bool)
    if valid.shape != (n, t1 - 1):
        raise DataError(f"{where}: valid must be [{n}, {t1 - 1}], got {valid.shape}")
    traj = Trajectories(
        torch.as_tensor(states, dtype=torch.float32), torch.as_tensor(actions, dtype=torch.float32),
        torch.zeros(n, t1 - 1), torch.as_tensor(valid), torch.zeros(n, dtype=torch.bool), dt,
    )
    return traj.truncate(horizon)


def save_trajectories(path: str | Path, traj: Trajectories, params: np.ndarray | None = None,
                      param_names: list[str] | None = None) -> None:
    """Write trajectories in the format `real=file` reads."""
    arrays = {"states": traj.states.numpy(), "actions": traj.actions.numpy(), "valid": traj.valid.numpy(),
              "dt": np.array(traj.dt)}
    if params is not None:
        arrays["params"] = np.asarray(params, float)
        arrays["param_names"] = np.array(param_names or [])
    np.savez(path, **arrays)


def surrogate(cfg: SurrogateConfig, task: Task, sims: SimulatorPool, prior, seed: int, **_: object) -> SurrogateReal:
    return SurrogateReal(cfg, task, sims, prior, seed)


def from_file(cfg: FileConfig, task: Task, **_: object) -> FileReal:
    return FileReal(cfg, task)

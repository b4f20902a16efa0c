"""The real data of a run read from a robot's log (real=lerobot, real=csv): what the two readers share.

A reader hashes every file it reads (`FileDigest`), names the episodes it holds, and hands the episodes,
resampled to the control rate by `Mapping.apply`, to `LogReal`; that checks them against collect.horizon with
the same validation as real=file (`load_trajectories`) when the run is built, before any simulation.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError
from ..real import load_trajectories
from ..sim.trajectories import Trajectories
from ..tasks.base import Task


class FileDigest:
    """SHA-256 over every file read, each with its path relative to the log's root, in reading order."""

    def __init__(self, root: Path):
        self.root, self._hash = root, hashlib.sha256()

    def read(self, path: Path) -> bytes:
        raw = path.read_bytes()  # read once: hashed and parsed
        self._hash.update(str(path.relative_to(self.root)).encode() + b"\0" + hashlib.sha256(raw).digest())
        return raw

    def hexdigest(self) -> str:
        return self._hash.hexdigest()


def log_path(text: str, option: str, what: str) -> Path:
    """The path a reader's config names, which must exist."""
    if text in ("???", ""):
        raise ConfigError(f"real={option} needs real.path=<{what}> (README.md, 'Real data from a robot')")
    path = Path(text).expanduser()
    if not path.exists():
        raise ConfigError(f"real.path={text!r}: no such {what}")
    return path


def select(available: list, wanted: list | None, where: str) -> list:
    """The episodes to use: all, in the log's order, or those named in real.episodes, in that order."""
    if wanted is None:
        return available
    missing = [e for e in wanted if e not in available]
    if missing:
        raise DataError(f"{where}: real.episodes names {missing}, which the log does not hold; it holds "
                        f"{', '.join(map(str, available))}")
    return list(wanted)


class LogReal:
    """Trajectories recorded on a real system, all given in the first round; true parameters unknown."""

    true_params = None

    def __init__(self, episodes: dict[str, tuple[np.ndarray, np.ndarray]], task: Task, fingerprint: str, where: str):
        if not episodes:
            raise DataError(f"{where}: the log holds no frames")
        self.episodes, self.task, self.fingerprint, self.where = episodes, task, fingerprint, where
        self._trajectories: Trajectories | None = None

    def check(self, horizon: int) -> None:
        """Stack the episodes, cut to the shortest, and validate them against the task and the horizon."""
        lengths = {e: len(actions) for e, (_, actions) in self.episodes.items()}
        short = {e: n for e, n in lengths.items() if n < horizon}
        if short:
            kept = [e for e in lengths if e not in short]
            raise DataError(f"{self.where}: episodes {', '.join(f'{e} ({n} steps)' for e, n in short.items())} are "
                            f"shorter than collect.horizon={horizon} control steps of {self.task.cfg.control_dt:g} s; "
                            f"leave them out (real.episodes=[{','.join(map(str, kept))}]) or run with "
                            f"collect.horizon={min(short.values())}")
        steps = min(lengths.values())
        data = {"states": np.stack([s[: steps + 1] for s, _ in self.episodes.values()]),
                "actions": np.stack([a[:steps] for _, a in self.episodes.values()]), "dt": self.task.cfg.control_dt}
        self._trajectories = load_trajectories(data, self.task, horizon, self.where)

    def collect(self, round_index: int, policy, horizon: int, seed: int) -> Trajectories | None:
        if round_index > 1:
            return None
        if self._trajectories is None:
            raise RuntimeError("LogReal.check(horizon) validates the log and must run before collect")
        return self._trajectories

"""Declared stages of a round: a name, what it reads, and a function from the round's context to an artifact.

A stage's result (a dict) is written atomically to `round_NNN/<name>.pt` before the next stage
starts; a finished stage is never rerun, so a killed run resumes where it stopped. Each stage draws
its randomness from `ctx.seed`, derived from the run's seed, the round and the stage's NAME: adding a
stage leaves every other stage's results unchanged.
"""

from __future__ import annotations

import contextvars
import copy
import dataclasses
import hashlib
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .artifacts import RunDir
    from .logging.tensorboard import NullTensorBoard, TensorBoardLogger

log = logging.getLogger(__name__)
_ROUND: contextvars.ContextVar[tuple[str, int] | None] = contextvars.ContextVar("round", default=None)
_SAID: set[tuple[tuple[str, int], str]] = set()  # (run directory and round, message) said so far


@dataclasses.dataclass(frozen=True)
class Stage:
    name: str
    run: Callable[[RoundContext], dict]
    inputs: tuple[str, ...] = ()  # stages of this round whose artifacts it reads
    # the artifact may be deleted once every stage that reads it is done (raw simulated trajectories)
    transient: bool = False


def stage_seed(seed: int, round_index: int, stage: str) -> int:
    """Independent, reproducible sub-seed per (seed, round, stage name)."""
    name = int.from_bytes(hashlib.sha256(stage.encode()).digest()[:4], "little")
    return int(np.random.SeedSequence([seed, round_index, name]).generate_state(1)[0])


def run_stage(ctx: RoundContext, stage: Stage) -> bool:
    """Run `stage` of ctx's round unless its artifact exists; save the artifact, with the stage's wall
    seconds, before returning. Returns whether it ran."""
    if ctx.has(stage.name):
        return False
    t0 = time.perf_counter()
    running = _ROUND.set((str(ctx.run_dir.path), ctx.round))
    try:
        out = stage.run(ctx.at(stage.name))
    finally:
        _ROUND.reset(running)
    out["seconds"] = time.perf_counter() - t0
    ctx.run_dir.save(ctx.round, stage.name, out)
    ctx.remember(stage.name, out)
    log.info("round %d: %s done in %.1f s", ctx.round, stage.name, out["seconds"])
    return True


def info_once_per_round(logger: logging.Logger, message: str) -> None:
    """logger.info(message) the first time the running round says it (a note from inside a loop would otherwise
    fill the console); every time outside a stage."""
    key = _ROUND.get()
    if key is not None:
        if (key, message) in _SAID:
            return
        _SAID.add((key, message))
    logger.info(message)


def check_stages(stages: list[Stage]) -> None:
    """Names are unique and every input is produced by an earlier stage."""
    seen: set[str] = set()
    for stage in stages:
        if stage.name in seen:
            raise ValueError(f"two stages are named {stage.name!r}")
        missing = [i for i in stage.inputs if i not in seen]
        if missing:
            raise ValueError(f"stage {stage.name!r} reads {missing}, which no earlier stage produces")
        seen.add(stage.name)


class RoundContext:
    """What a stage sees: the round, its seed, the TensorBoard logger and earlier artifacts. The stage's own
    objects (simulators, prior, ...) come with the object the stage belongs to, not through here."""

    def __init__(self, run_dir: RunDir, round_index: int, seed: int, tb: TensorBoardLogger | NullTensorBoard,
                 stage: str = ""):
        self.run_dir, self.round, self.run_seed, self.tb, self.stage = run_dir, round_index, seed, tb, stage
        self._cache: dict[tuple[int, str], dict] = {}

    def at(self, stage: str) -> RoundContext:
        """This round's context for `stage`: seeded by its name, sharing the artifacts loaded so far."""
        bound = copy.copy(self)
        bound.stage = stage
        return bound

    @property
    def seed(self) -> int:
        return stage_seed(self.run_seed, self.round, self.stage)

    def has(self, stage: str, round_index: int | None = None) -> bool:
        return self.run_dir.has(self.round if round_index is None else round_index, stage)

    def output(self, stage: str, round_index: int | None = None) -> dict:
        """The artifact of `stage` in this round or an earlier one (loaded once)."""
        key = (self.round if round_index is None else round_index, stage)
        if key not in self._cache:
            if not self.run_dir.has(*key):
                raise FileNotFoundError(f"round {key[0]} has no finished {stage!r} stage in {self.run_dir.path}")
            self._cache[key] = self.run_dir.load(*key)
        return self._cache[key]

    def remember(self, stage: str, artifact: dict) -> None:
        self._cache[(self.round, stage)] = artifact

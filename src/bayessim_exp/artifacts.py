"""Run directory layout and atomic writes: every finished stage survives a killed run.

    <run dir>/config.yaml           the composed config (a resumed run must match it)
    <run dir>/results.json          what sweeps and reports read (README, 'Sweeps, launchers and reports')
    <run dir>/round_001/<stage>.pt  one artifact per finished stage, a data file (data_files.py)
    <run dir>/events.out.tfevents.* TensorBoard
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from .data_files import dumps, load_state
from .errors import ConfigError


def _atomic_write(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class RunDir:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)

    def stage_file(self, round_index: int, stage: str) -> Path:
        return self.path / f"round_{round_index:03d}" / f"{stage}.pt"

    def has(self, round_index: int, stage: str) -> bool:
        return self.stage_file(round_index, stage).is_file()

    def save(self, round_index: int, stage: str, obj: Any) -> None:
        data = dumps(obj)
        _atomic_write(self.stage_file(round_index, stage), lambda f: f.write(data))

    def load(self, round_index: int, stage: str, trusted: bool = False) -> Any:
        return load_state(self.stage_file(round_index, stage), trusted,
                          convert_hint=f"bayessim_exp.api.load_run({str(self.path)!r}, trusted=True) rewrites "
                                       "the run's artifacts")

    def convert(self) -> None:
        """Rewrite every artifact as a data file; those in the old pickle format are unpickled (running any
        code they hold), so only for run dirs from a trusted source."""
        for path in sorted(self.path.glob("round_*/*.pt")):
            round_index, stage = int(path.parent.name.removeprefix("round_")), path.stem
            self.save(round_index, stage, self.load(round_index, stage, trusted=True))

    def write_json(self, name: str, obj: Any) -> None:
        """Strict JSON: NaN and infinities (e.g. the log density of a point outside the support) become null."""
        text = json.dumps(_finite_or_null(obj), indent=2, allow_nan=False)
        _atomic_write(self.path / name, lambda f: f.write(text.encode()))

    def bind_fingerprint(self, name: str, fingerprint: str | None) -> None:
        """Record the hash of an input outside the config (a data file); a run dir made from other
        contents is refused, as one made with another config is."""
        if fingerprint is None:
            return
        stored = self.path / f"{name.replace(' ', '_')}.sha256"
        if stored.is_file() and stored.read_text().strip() != fingerprint:
            raise ConfigError(f"{self.path} holds a run made from other {name} (SHA-256 {stored.read_text().strip()[:12]}..., "
                              f"now {fingerprint[:12]}...); the file changed since: use a new run dir")
        if not stored.is_file():
            _atomic_write(stored, lambda f: f.write(fingerprint.encode()))

    def bind_config(self, cfg: DictConfig) -> None:
        """Record the config; a run dir that holds another config's stages is refused."""
        text = OmegaConf.to_yaml(cfg, resolve=True)
        stored = self.path / "config.yaml"
        if stored.is_file():
            if stored.read_text() != text:
                old, new = OmegaConf.create(stored.read_text()), OmegaConf.create(text)
                diff = sorted(_diff_keys(OmegaConf.to_container(old), OmegaConf.to_container(new)))
                raise ConfigError(
                    f"{self.path} holds a run with another config (differs at: {', '.join(diff[:8])}); "
                    "resume with the same overrides or use a new run dir"
                )
            return
        _atomic_write(stored, lambda f: f.write(text.encode()))


def _finite_or_null(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_null(v) for v in obj]
    return obj


def _diff_keys(a: Any, b: Any, prefix: str = "") -> set[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out: set[str] = set()
        for k in set(a) | set(b):
            out |= _diff_keys(a.get(k), b.get(k), f"{prefix}{k}.")
        return out
    return set() if a == b else {prefix.rstrip(".")}

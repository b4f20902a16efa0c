"""A sweep's jobs as found on disk: their overrides, results.json, and whether they finished.

A job dir is any dir under the sweep dir holding `.hydra/`, `results.json` or `error.txt` (the
entry writes the error of a failed job there). A job is
  finished    results.json has every configured round (and no newer error.txt),
  failed      error.txt is newer than results.json, or results.json cannot be read,
  unfinished  no results.json yet, or fewer rounds than configured (killed, still running).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import yaml

_ROUND_KEYS = ("rounds",)  # the run config key holding the number of rounds


@dataclasses.dataclass
class Job:
    path: Path
    overrides: list[str]
    results: dict | None
    expected_rounds: int | None
    status: str  # finished | failed | unfinished
    problem: str = ""  # why a job is failed or unfinished

    @property
    def seed(self) -> int | None:
        if self.results is not None:
            return self.results.get("seed")
        value = _override_value(self.overrides, "seed")
        return int(value) if value is not None and value.lstrip("-").isdigit() else None


def _override_value(overrides: list[str], key: str) -> str | None:
    for item in overrides:
        name, _, value = item.lstrip("+~").partition("=")
        if name == key:
            return value
    return None


def _is_job_dir(path: Path) -> bool:
    return (path / ".hydra").is_dir() or (path / "results.json").is_file() or (path / "error.txt").is_file()


def find_job_dirs(sweep_dir: Path) -> list[Path]:
    """Job dirs under sweep_dir (itself included), not descending into a job or into hidden dirs."""
    if _is_job_dir(sweep_dir):
        return [sweep_dir]
    found = []
    for child in sorted(p for p in sweep_dir.iterdir() if p.is_dir() and not p.name.startswith(".")):
        found += find_job_dirs(child)
    return sorted(found, key=_job_order)


def _job_order(path: Path):
    """Hydra's job number first (the `<num>_` prefix of the dir name), then the path."""
    head = path.name.split("_", 1)[0]
    return (int(head) if head.isdigit() else float("inf"), str(path))


def _read_yaml(path: Path):
    try:
        return yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError):
        return None


def _expected_rounds(path: Path) -> int | None:
    for name in ("config.yaml", ".hydra/config.yaml"):
        cfg = _read_yaml(path / name)
        if isinstance(cfg, dict):
            for key in _ROUND_KEYS:
                if isinstance(cfg.get(key), int):
                    return cfg[key]
    return None


def _last_line(path: Path) -> str:
    try:
        lines = [line.strip() for line in path.read_text(errors="replace").splitlines() if line.strip()]
    except OSError as exc:
        return f"error.txt unreadable: {exc}"
    return (lines[-1] if lines else "(error.txt is empty)")[:300]


def read_job(path: Path) -> Job:
    overrides = _read_yaml(path / ".hydra" / "overrides.yaml")
    overrides = [str(o) for o in overrides] if isinstance(overrides, list) else []
    expected = _expected_rounds(path)
    results_file, error_file = path / "results.json", path / "error.txt"
    results = None
    if results_file.is_file():
        try:
            results = json.loads(results_file.read_text())
            if not isinstance(results, dict) or not isinstance(results.get("rounds"), list):
                raise ValueError("no 'rounds' list")
        except (OSError, ValueError) as exc:
            return Job(path, overrides, None, expected, "failed", f"results.json unreadable: {exc}")
    if error_file.is_file() and (results is None or error_file.stat().st_mtime >= results_file.stat().st_mtime):
        return Job(path, overrides, results, expected, "failed", _last_line(error_file))
    if results is None:
        return Job(path, overrides, None, expected, "unfinished", "no results.json")
    done = len(results["rounds"])
    expected = results.get("rounds_planned", expected)  # with the rounds the method added (absent in older runs)
    if done == 0 or (expected is not None and done < expected):
        return Job(path, overrides, results, expected, "unfinished", f"{done} of {expected} rounds")
    return Job(path, overrides, results, expected, "finished")


def read_jobs(sweep_dir: str | Path) -> list[Job]:
    sweep_dir = Path(sweep_dir)
    if not sweep_dir.is_dir():
        raise FileNotFoundError(f"{sweep_dir} is not a directory")
    return [read_job(p) for p in find_job_dirs(sweep_dir)]


def configuration_labels(jobs: list[Job], pool: bool = False) -> dict[Path, str]:
    """A label per job naming what sets its configuration apart: its overrides without the seed
    and without those every job shares (from results.json's components when there are none);
    `pool`: one label for all, a study whose parts ran elsewhere (other machines, devices)."""
    if pool:
        return {job.path: "pooled" for job in jobs}
    keyed = {}
    for job in jobs:
        items = [o for o in job.overrides if _override_key(o) != "seed" and not _override_key(o).startswith("hydra.")]
        if not items and job.results is not None:
            items = [f"{k}={job.results[k]}" for k in ("task", "method", "model", "summarizer", "policy")
                     if job.results.get(k) is not None]
        keyed[job.path] = items
    shared = set.intersection(*(set(v) for v in keyed.values())) if keyed else set()
    return {path: " ".join(o for o in items if o not in shared) or "all" for path, items in keyed.items()}


def _override_key(item: str) -> str:
    return item.lstrip("+~").partition("=")[0]

"""real=csv: a plain table of a robot's log as real trajectories.

real.path is a .csv file or a directory of them (*.csv, read in name order). The first line names the columns;
every row is a frame: a time column (seconds times real.time_scale), and columns named after the task's
observations and actuators (or mapped to them, as real=lerobot maps features). A file is one episode, named by
the file's stem, unless real.episode_column names a column whose value tells the episode of each row.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import io
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, DataError
from ..tasks.base import Task
from .log_real import FileDigest, LogReal, log_path, select
from .mapping import Mapping


@dataclasses.dataclass
class CsvConfig:
    path: str
    time_column: str
    time_scale: float
    episode_column: str | None
    episodes: list[str] | None
    observations: dict[str, Any] | None
    actions: dict[str, Any] | None
    actions_normalised: bool

    def validate(self) -> None:
        if not self.time_scale > 0:
            raise ConfigError(f"time_scale must be > 0 (seconds per unit of the time column), got {self.time_scale}")


def _table(text: str, where: str) -> tuple[list[str], np.ndarray]:
    """CSV text -> (column names, values [rows, columns]); an empty cell is NaN, reported where it is used."""
    lines = list(csv.reader(io.StringIO(text)))
    if not lines or not any(c.strip() for c in lines[0]):
        raise DataError(f"{where}: empty; the first line must name the columns")
    header = [c.strip() for c in lines[0]]
    body = [row for row in lines[1:] if row]
    values = np.full((len(body), len(header)), np.nan)
    for r, row in enumerate(body):
        if len(row) != len(header):
            raise DataError(f"{where}: line {r + 2} has {len(row)} cells for {len(header)} columns")
        for c, cell in enumerate(row):
            try:
                values[r, c] = float(cell) if cell.strip() else np.nan
            except ValueError:
                raise DataError(f"{where}: line {r + 2}, column {header[c]}: {cell!r} is not a number") from None
    return header, values


def _column(header: list[str], name: str, option: str, where: str) -> int:
    if name not in header:
        close = difflib.get_close_matches(name, header, n=1)
        hint = f" (closest: {close[0]})" if close else ""
        raise DataError(f"{where}: no column {name!r} for real.{option}{hint}; columns: {', '.join(header)}")
    return header.index(name)


def read(cfg: CsvConfig, task: Task) -> LogReal:
    path = log_path(cfg.path, "csv", "CSV file or directory of CSV files")
    root = path if path.is_dir() else path.parent
    files = sorted(path.glob("*.csv")) if path.is_dir() else [path]
    if not files:
        raise ConfigError(f"real.path={cfg.path!r}: a directory without *.csv files")
    digest = FileDigest(root)
    tables: dict[Path, tuple[list[str], np.ndarray]] = {}
    for file in files:
        try:
            tables[file] = _table(digest.read(file).decode("utf-8-sig"), str(file))
        except UnicodeDecodeError as exc:
            raise DataError(f"{file}: not a text file ({exc})") from None
    header = tables[files[0]][0]
    for file, (other, _) in tables.items():
        if set(other) != set(header):
            raise DataError(f"{file}: columns {other} differ from {files[0].name}'s {header}; one log, one set of columns")
    special = [cfg.time_column] + ([cfg.episode_column] if cfg.episode_column else [])
    schema = {c: ("0",) for c in header if c not in special}
    mapping = Mapping(cfg.observations, cfg.actions, cfg.actions_normalised, task, schema, str(path))
    rows: dict[str, tuple[str, np.ndarray, list[str]]] = {}  # episode -> (where, values, columns)
    for file, (names, values) in tables.items():
        _column(names, cfg.time_column, "time_column", str(file))  # present in every file
        if cfg.episode_column is None:
            rows[file.stem] = (str(file), values, names)
            continue
        column = values[:, _column(names, cfg.episode_column, "episode_column", str(file))]
        for value in dict.fromkeys(column.tolist()):
            episode = f"{value:g}"
            if episode in rows:
                raise DataError(f"{file}: episode {episode} also appears in {rows[episode][0]}; number the episodes of "
                                "different files apart")
            rows[episode] = (str(file), values[column == value], names)
    episodes = {}
    for e in select(list(rows), cfg.episodes, str(path)):
        file, values, names = rows[e]
        where = f"{file} episode {e}" if cfg.episode_column else file
        columns = {c: values[:, [names.index(c)]] for c in mapping.features}
        times = values[:, names.index(cfg.time_column)] * cfg.time_scale
        episodes[e] = mapping.apply(times, columns, where)
    return LogReal(episodes, task, digest.hexdigest(), str(path))


def from_csv(cfg: CsvConfig, task: Task, **_: object) -> LogReal:
    return read(cfg, task)

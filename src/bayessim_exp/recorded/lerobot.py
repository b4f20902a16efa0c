"""real=lerobot: a LeRobot dataset directory (codebase v2.x or v3.0) as real trajectories.

What is read: meta/info.json (`codebase_version`, `fps`, `features` with each feature's `shape` and element
`names`, the `data_path` template and `chunks_size`) and the parquet files under data/: one file per episode in
v2 (data/chunk-XXX/episode_XXXXXX.parquet), several episodes per file in v3 (data/chunk-XXX/file-XXX.parquet).
Each row is a frame of one episode (`episode_index`), stamped with `timestamp` in seconds from the episode's
start; a vector feature is a list column. Videos, images and the other metadata files are not read.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, DataError
from ..tasks.base import Task
from .log_real import FileDigest, LogReal, log_path, select
from .mapping import Mapping, Schema, element_labels

# LeRobot's own bookkeeping columns: frame order and identity, never an observation or an action
BOOKKEEPING = ("timestamp", "frame_index", "episode_index", "index", "task_index")
FPS_TOLERANCE = 0.01  # relative disagreement of info.json's fps and the time stamps that is a wrong fps


@dataclasses.dataclass
class LeRobotConfig:
    path: str
    episodes: list[int] | None
    observations: dict[str, Any] | None
    actions: dict[str, Any] | None
    actions_normalised: bool


def _parquet():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ConfigError("real=lerobot reads parquet files with pyarrow, which is not installed: "
                          "pip install 'bayessim_exp[robot]' (or pip install pyarrow)") from None
    return pa, pq


def _schema(features: dict, where: str) -> Schema:
    """The numeric one-dimensional features, by element: LeRobot's `names` is a list, a {group: list} mapping
    (some v2.0 datasets) or null."""
    schema = {}
    for name, spec in features.items():
        shape = spec.get("shape") if isinstance(spec, dict) else None
        if name in BOOKKEEPING or not shape or len(shape) != 1 or spec.get("dtype") in ("video", "image", "string"):
            continue
        names = spec.get("names")
        if isinstance(names, dict):
            names = next((v for v in names.values() if isinstance(v, list)), None)
        schema[name] = element_labels(int(shape[0]), names if isinstance(names, list) else None)
    if not schema:
        raise DataError(f"{where}: meta/info.json declares no numeric vector features (features: {sorted(features)})")
    return schema


def _data_files(root: Path, info: dict, episodes: list[int] | None) -> list[Path]:
    template = info.get("data_path")
    if not isinstance(template, str):
        raise DataError(f"{root}: meta/info.json has no data_path template (e.g. "
                        "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet)")
    if episodes is not None and "{episode_index" in template:  # v2: the selected episodes' files only
        chunk = int(info.get("chunks_size", 1000))
        try:
            files = [root / template.format(episode_chunk=e // chunk, episode_index=e) for e in episodes]
        except (KeyError, IndexError, ValueError) as exc:
            raise DataError(f"{root}: meta/info.json's data_path {template!r} cannot be filled ({exc})") from None
        missing = [str(f.relative_to(root)) for f, e in zip(files, episodes) if not f.is_file()]
        if missing:
            raise DataError(f"{root}: real.episodes={episodes} names episodes with no data file ({', '.join(missing)})")
        return files
    files = sorted(root.glob(re.sub(r"\{[^}]*\}", "*", template)))
    if not files:
        raise DataError(f"{root}: no data file matches meta/info.json's data_path {template!r}")
    return files


def _columns(pa, table, names: list[str], schema: Schema, where: str) -> dict[str, np.ndarray]:
    """Arrow columns -> arrays [rows, width]; a vector feature is a list column."""
    out = {}
    for name in names:
        column = table.column(name).combine_chunks()
        kind = column.type
        if pa.types.is_list(kind) or pa.types.is_large_list(kind) or pa.types.is_fixed_size_list(kind):
            values = column.flatten().to_numpy(zero_copy_only=False).astype(float)
        else:
            values = column.to_numpy(zero_copy_only=False).astype(float)
        width = len(schema.get(name, (0,)))
        if values.size != len(table) * width:
            raise DataError(f"{where}: column {name} holds {values.size} values for {len(table)} rows of "
                            f"{width} (missing values, or lists of another width than meta/info.json's shape)")
        out[name] = values.reshape(len(table), width)
    return out


def read(cfg: LeRobotConfig, task: Task) -> LogReal:
    root = log_path(cfg.path, "lerobot", "LeRobot dataset directory")
    pa, pq = _parquet()
    info_path = root / "meta" / "info.json"
    if not info_path.is_file():
        present = sorted(p.name for p in root.iterdir()) if root.is_dir() else []
        raise DataError(f"{root}: no meta/info.json; a LeRobot dataset directory holds meta/info.json and data/ "
                        f"(codebase v2.x or v3.0); this one holds {present}")
    digest = FileDigest(root)
    try:
        info = json.loads(digest.read(info_path))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{info_path}: not JSON ({exc})") from None
    version = str(info.get("codebase_version", ""))
    if not version.startswith(("v2", "v3")):
        raise DataError(f"{info_path}: codebase_version={version or None!r}; real=lerobot reads v2.x and v3.0 datasets")
    fps = info.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
        raise DataError(f"{info_path}: fps={fps!r}; it must be the frames per second, a positive number")
    if not isinstance(info.get("features"), dict):
        raise DataError(f"{info_path}: no features mapping (feature name -> dtype, shape, names)")
    schema = _schema(info["features"], str(info_path))
    mapping = Mapping(cfg.observations, cfg.actions, cfg.actions_normalised, task, schema, str(info_path))
    timed = "timestamp" in info["features"]
    frames: dict[int, list[dict[str, np.ndarray]]] = {}
    for path in _data_files(root, info, cfg.episodes):
        where = str(path.relative_to(root))
        try:
            table = pq.read_table(pa.BufferReader(digest.read(path)))
        except pa.ArrowException as exc:
            raise DataError(f"{root}: {where} is not a readable parquet file ({exc})") from None
        wanted = [*mapping.features, "episode_index", *(["timestamp"] if timed else [])]
        absent = [c for c in wanted if c not in table.column_names]
        if absent:
            raise DataError(f"{root}: {where} has no column {', '.join(absent)} although meta/info.json declares "
                            f"it; its columns: {', '.join(table.column_names)}")
        columns = _columns(pa, table, wanted, schema, f"{root}: {where}")
        index = columns.pop("episode_index")[:, 0].astype(int)
        for e in dict.fromkeys(index.tolist()):
            frames.setdefault(e, []).append({k: v[index == e] for k, v in columns.items()})
    episodes = {}
    for e in select(sorted(frames), cfg.episodes, str(root)):
        columns = {k: np.concatenate([part[k] for part in frames[e]]) for k in frames[e][0]}
        times = columns.pop("timestamp")[:, 0] if timed else np.arange(len(columns[mapping.features[0]])) / fps
        where = f"{root} episode {e}"
        steps = np.diff(times)
        if steps.size and np.isfinite(steps).all() and abs(np.median(steps) * fps - 1) > FPS_TOLERANCE:
            step = float(np.median(steps))
            raise DataError(f"{where}: meta/info.json gives fps={fps:g} but the time stamps step by {step:g} s "
                            f"({1 / step:g} Hz); correct fps or the timestamp column")
        episodes[str(e)] = mapping.apply(times, columns, where)
    return LogReal(episodes, task, digest.hexdigest(), str(root))


def from_lerobot(cfg: LeRobotConfig, task: Task, **_: object) -> LogReal:
    return read(cfg, task)

"""Write small robot logs in LeRobot's layout (v2.x, v3.0) and as CSV tables, for the tests of real=lerobot and
real=csv and for benchmarks/own_robot.py: nothing is downloaded. An episode is {feature: values [frames, width]},
frame i stamped i / fps."""

import csv
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

V2_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V3_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
NAMES = {"observation.state": ["cos_theta", "sin_theta", "theta_dot"], "action": ["torque"]}  # Pendulum's own


def pendulum_frames(states: np.ndarray, actions: np.ndarray) -> list[dict[str, np.ndarray]]:
    """Trajectories' arrays [n, T+1, 3] and [n, T, 1] -> episodes as LeRobot records them: the state of each frame
    and the torque in N m (control range [-2, 2]) commanded after it; the last frame's command was never applied."""
    torque = 2.0 * np.concatenate([actions, actions[:, -1:]], 1)
    return [{"observation.state": np.array(s), "action": a} for s, a in zip(states, torque)]  # copies: edited by tests


def write_lerobot(root: Path, episodes: list[dict[str, np.ndarray]], names: dict[str, list[str] | None],
                  fps: float = 20.0, version: str = "v3.0", times=None) -> Path:
    """A dataset directory; v3.0 puts the episodes into two files (fixed-size list columns), v2.1 one file per
    episode (list columns). `times(e, frames)` overrides the time stamps of episode e."""
    root.mkdir(parents=True, exist_ok=True)
    features = {name: {"dtype": "float32", "shape": [episodes[0][name].shape[1]], "names": names.get(name)}
                for name in episodes[0]}
    for name in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        features[name] = {"dtype": "float32" if name == "timestamp" else "int64", "shape": [1], "names": None}
    tables, start = [], 0
    for e, episode in enumerate(episodes):
        frames = len(next(iter(episode.values())))
        stamps = np.arange(frames) / fps if times is None else times(e, frames)
        columns = {}
        for name, values in episode.items():
            flat = pa.array(values.astype(np.float32).ravel())
            columns[name] = (pa.FixedSizeListArray.from_arrays(flat, values.shape[1]) if version.startswith("v3")
                             else pa.ListArray.from_arrays(pa.array(np.arange(frames + 1) * values.shape[1],
                                                                    pa.int32()), flat))
        columns["timestamp"] = pa.array(stamps.astype(np.float32))
        columns["frame_index"] = pa.array(np.arange(frames))
        columns["episode_index"] = pa.array(np.full(frames, e))
        columns["index"] = pa.array(start + np.arange(frames))
        columns["task_index"] = pa.array(np.zeros(frames, np.int64))
        tables.append(pa.table(columns))
        start += frames
    if version.startswith("v3"):
        half = (len(tables) + 1) // 2
        files = {V3_PATH.format(chunk_index=0, file_index=k): part for k, part in enumerate([tables[:half], tables[half:]])
                 if part}
        files = {path: pa.concat_tables(part) for path, part in files.items()}
    else:
        files = {V2_PATH.format(episode_chunk=0, episode_index=e): t for e, t in enumerate(tables)}
    for path, table in files.items():
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, root / path)
    info = {"codebase_version": version, "robot_type": "pendulum", "total_episodes": len(episodes),
            "total_frames": start, "chunks_size": 1000, "fps": fps, "data_path": V3_PATH if version.startswith("v3")
            else V2_PATH, "features": features}
    (root / "meta").mkdir(exist_ok=True)
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=2))
    return root


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """One table: column name -> values [rows]."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(columns)
        out.writerows(zip(*(np.asarray(v).tolist() for v in columns.values())))
    return path

"""Simulations from a task's prior, cached on disk, for the many-parameter inference benchmark.

    OMP_NUM_THREADS=1 PYTHONPATH=src python3 benchmarks/task_simulations.py --task Ant --sims 21000

Draws parameters from the task's prior, rolls the collect policy out with the native backend
exactly as the pipeline's collect stage does (`SimulatorPool.rollout`), and stores theta and the raw
trajectories in `<cache>/<task>_h<horizon>_seed<seed>_<fingerprint>.pt` (the fingerprint changes with
the task's config and compiled model), so that every summarizer and model of the benchmark reads the
same simulations. A request for more simulations than are cached extends
the file (new rows come from a seed derived from the chunk index: the prefix never changes).
"""

from __future__ import annotations

import argparse
import hashlib
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from bayessim_exp import api, registry
from bayessim_exp.components import build_components
from bayessim_exp.run_config import check_run_config
from bayessim_exp.sim.trace_cache import model_bytes
from bayessim_exp.sim.trajectories import Trajectories

DEFAULT_CACHE = Path("/tmp/bayessim_inference_tasks")
_BLOCK = 2048  # simulations per cached block; each block has its own seed


def components(task: str, policy: str = "random", summarizer: str = "start", nthread: int = 0):
    """Native simulation on `nthread` CPU threads (0: all), also on a machine with a GPU (sim=auto would take MJX)."""
    cfg = api.compose([f"task={task}", f"policy={policy}", f"summarizer={summarizer}", "sim=native",
                       f"sim.nthread={nthread}"])
    return cfg, build_components(cfg, check_run_config(cfg))


def fingerprint(task: str) -> str:
    """Of the task's config and compiled model: simulations of an earlier version are not reused."""
    cfg = api.compose([f"task={task}"])
    model = registry.build("task", cfg.task).model
    return hashlib.sha1(OmegaConf.to_yaml(cfg.task).encode() + model_bytes(model)).hexdigest()[:10]


def _simulate_block(comp, block: int, n: int, horizon: int, seed: int) -> tuple[torch.Tensor, Trajectories]:
    block_seed = int(np.random.SeedSequence([seed, block]).generate_state(1)[0])
    with torch.random.fork_rng():
        torch.manual_seed(block_seed)
        theta = comp.prior.sample((n,)).double()
    traj = comp.sims.rollout(theta, comp.policy(block_seed), horizon, block_seed)
    return theta, traj


def load_simulations(task: str, sims: int, horizon: int = 50, seed: int = 0, cache: Path = DEFAULT_CACHE,
                     verbose: bool = True, nthread: int = 0,
                     seconds: float = float("inf")) -> tuple[torch.Tensor, Trajectories, float]:
    """(theta [n, D], trajectories, simulation seconds per 1000 trajectories) for `task` under its prior
    and the random collect policy; simulates only what the cache lacks. n = sims, or fewer when simulating
    the missing blocks takes longer than `seconds` (no new block starts after that)."""
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{task}_h{horizon}_seed{seed}_{fingerprint(task)}.pt"
    stored = torch.load(path, weights_only=False) if path.exists() else {"theta": [], "traj": [], "seconds": 0.0}
    have = cached = sum(len(t) for t in stored["theta"])
    if have < sims:
        _, comp = components(task, nthread=nthread)
        start = time.perf_counter()
        while have < sims and time.perf_counter() - start < seconds:
            block = len(stored["theta"])
            t0 = time.perf_counter()
            theta, traj = _simulate_block(comp, block, _BLOCK, horizon, seed)
            stored["seconds"] += time.perf_counter() - t0
            stored["theta"].append(theta)
            stored["traj"].append(traj.state_dict())
            have += len(theta)
            if verbose:
                print(f"{task}: {have} simulations ({stored['seconds']:.0f} s)", flush=True)
        if have > cached:
            tmp = path.with_suffix(".tmp")
            torch.save(stored, tmp)
            tmp.replace(path)  # atomic: an interrupted run never leaves a truncated cache
    n = min(sims, have)
    theta = torch.cat(stored["theta"])[:n]
    traj = Trajectories.cat([Trajectories(**t) for t in stored["traj"]]).select(torch.arange(n))
    return theta, traj, 1000 * stored["seconds"] / have


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", required=True, nargs="+")
    parser.add_argument("--sims", type=int, required=True)
    parser.add_argument("--horizon", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--nthread", type=int, default=0, help="simulation threads (0: all CPUs)")
    parser.add_argument("--seconds", type=float, default=float("inf"), help="start no new block after this long")
    args = parser.parse_args()
    torch.set_num_threads(1)
    for task in args.task:
        load_simulations(task, args.sims, args.horizon, args.seed, args.cache, nthread=args.nthread, seconds=args.seconds)


if __name__ == "__main__":
    main()

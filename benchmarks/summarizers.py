"""Time per 10,000 trajectories for every summarizer, pysiglib against the plain-torch signature.

    OMP_NUM_THREADS=1 PYTHONPATH=src python3 benchmarks/summarizers.py [--device cuda] [--repeats 3]

Trajectories are random (T=50 steps, 6 state + 2 action channels by default) with a fifth of
them ending early, so the masking is part of what is timed. Prints a markdown table: the best
of `repeats` timed calls after one warm-up call, scaled to 10,000 trajectories.
"""

from __future__ import annotations

import argparse
import platform
import time

import torch

from bayessim_exp import registry
from bayessim_exp.sim.trajectories import Trajectories

CASES = [
    ("start", {"steps": 20}),
    ("waypoints", {"steps": 20}),
    ("corr", {"lags": 2}),
    ("corrdiff", {"lags": 2}),
    ("learned", {"time_points": 20}),
    ("signatory", {"depth": 2}),
    ("signatory", {"depth": 2, "backend": "torch"}),
    ("signatory", {"depth": 3}),
    ("signatory", {"depth": 3, "backend": "torch"}),
    ("signatory", {"depth": 3, "log_signature": True}),
    ("signatory", {"depth": 3, "log_signature": True, "backend": "torch"}),
    ("signatory", {"depth": 3, "lead_lag": True}),
    ("signatory", {"depth": 3, "lead_lag": True, "backend": "torch"}),
]


def random_trajectories(n: int, horizon: int, state_dim: int, action_dim: int, device: str) -> Trajectories:
    g = torch.Generator().manual_seed(0)
    states = torch.randn(n, horizon + 1, state_dim, generator=g).cumsum(1)
    actions = torch.rand(n, horizon, action_dim, generator=g) * 2 - 1
    ends = torch.where(torch.rand(n, generator=g) < 0.2, torch.randint(1, horizon, (n,), generator=g), horizon)
    valid = torch.arange(horizon)[None] < ends[:, None]
    return Trajectories(states, actions * valid[..., None], torch.zeros(n, horizon), valid,
                        torch.zeros(n, dtype=torch.bool), 0.05).to(device)


def seconds(fn, repeats: int, device: str) -> float:
    def timed() -> float:
        start = time.perf_counter()
        fn()
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        return time.perf_counter() - start

    timed()  # warm-up: pysiglib's log-signature basis, lazy layers, CUDA kernels
    return min(timed() for _ in range(repeats))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectories", type=int, default=10_000)
    parser.add_argument("--horizon", type=int, default=50)
    parser.add_argument("--state-dim", type=int, default=6)
    parser.add_argument("--action-dim", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()

    traj = random_trajectories(args.trajectories, args.horizon, args.state_dim, args.action_dim, args.device)
    scale = 10_000 / args.trajectories
    print(f"# {args.trajectories} trajectories, T={args.horizon}, {args.state_dim} state + {args.action_dim} action "
          f"channels, float32, device {args.device}, torch {torch.__version__} ({torch.get_num_threads()} threads), "
          f"{platform.processor() or platform.machine()}")
    print("| summarizer | options | output dim | s per 10,000 trajectories | torch reference / pysiglib |")
    print("|---|---|---|---|---|")
    pysiglib_seconds: dict[str, float] = {}
    for name, params in CASES:
        summarizer = registry.build("summarizer", {"name": name, **params})
        dim = summarizer.output_dim(args.state_dim, args.action_dim, args.horizon)
        options = ", ".join(f"{k}={v}" for k, v in params.items())
        with torch.no_grad():
            s = seconds(lambda f=summarizer: f(traj), args.repeats, args.device)
        ratio = ""
        if name == "signatory":  # the torch row follows the pysiglib row with the same other options
            same = ", ".join(f"{k}={v}" for k, v in params.items() if k != "backend")
            if params.get("backend") == "torch":
                ratio = f"{s / pysiglib_seconds[same]:.1f}x"
            else:
                pysiglib_seconds[same] = s
        print(f"| {name} | {options} | {dim} | {s * scale:.4f} | {ratio} |", flush=True)
        if hasattr(summarizer, "embedding"):
            summarizer.embedding.to(args.device)
            with torch.no_grad():
                s = seconds(lambda f=summarizer: f.embedding(f(traj)), args.repeats, args.device)
            print(f"| {name} + embedding forward | {options} | {summarizer.embedding_dim} | {s * scale:.4f} | |", flush=True)


if __name__ == "__main__":
    main()

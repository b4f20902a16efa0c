"""The CPU Adam step of models/adam.py against torch.optim.Adam's single-tensor path (what it reproduces bit for
bit), on the parameters of the default mixture network (80 summary features, two hidden layers of 128).

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/adam_step.py [--steps 2000] [--repeats 5]

Prints microseconds per step, the best and the median of the repeats, for both.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from bayessim_exp.models.adam import Adam


def per_step(optimizer, steps: int, repeats: int) -> list[float]:
    for _ in range(50):
        optimizer.step()
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            optimizer.step()
        out.append((time.perf_counter() - start) / steps * 1e6)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.manual_seed(0)
    rows = []
    for name, build in (("torch.optim.Adam (foreach=False)", lambda p: torch.optim.Adam(p, lr=1e-3, foreach=False)),
                        ("models/adam.py Adam", lambda p: Adam(p, lr=1e-3))):
        net = torch.nn.Sequential(torch.nn.Linear(80, 128), torch.nn.ReLU(), torch.nn.Linear(128, 128),
                                  torch.nn.ReLU(), torch.nn.Linear(128, 30))
        for p in net.parameters():
            p.grad = torch.randn_like(p)
        rows.append((name, per_step(build(list(net.parameters())), args.steps, args.repeats)))
    print(f"torch {torch.__version__}, {torch.get_num_threads()} thread(s); microseconds per Adam step")
    print(f"{'optimiser':<36}{'best':>8}{'median':>9}")
    for name, times in rows:
        print(f"{name:<36}{min(times):>8.1f}{statistics.median(times):>9.1f}")


if __name__ == "__main__":
    main()

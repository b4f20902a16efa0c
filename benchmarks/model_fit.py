"""Posterior-model training speed: the same fit on the CPU and on a GPU, eager and from a CUDA graph.

    python benchmarks/model_fit.py [--models mdnn mdrff flow] [--sims 10000] [--epochs 20]
        [--theta-dim 2] [--x-dim 6] [--batch-size 256] [--set ensemble=1] [--threads 16 8] [--box]

Synthetic pairs (x = A theta + noise) of the pipeline's default size; every fit runs exactly
`--epochs` epochs (patience = epochs), so rows compare the same work. Rows per model: `cpu` (the
baseline, the machine's torch threads), `cuda eager` (one kernel launch at a time) and `cuda graph`
(the step replayed from a CUDA graph, what the pipeline does with device=cuda); with `--threads`, one
`cpu` row per torch thread count (the first is the baseline; training uses at most
models/base.CPU_TRAINING_THREADS of them, which the row names). `--set` overrides the models' config
(`--set ensemble=3 covariance=full components=1`: the mission's ShadowHand model). Mixture models (mdnn,
mdrff) get a `matrix loss` row per device as well: the loss by autograd through the assembled precision
factors (`mixture_nll`) instead of the head's loss with its written-out gradient (`HeadNLL`).
`--box`: mdnn gets a `box-truncated` row per device as well, the fit of box space's truncated mixture (the
parameters' box [0, 1]^D, models/box_mass.py), whose `cuda graph` row says whether that loss is captured.
"""

from __future__ import annotations

import argparse
import os
import time

import torch
import yaml

from bayessim_exp.models import adam_steps, base, mdnn
from bayessim_exp.models.mixture_nll import mixture_nll
from bayessim_exp.registry import build

HEAD_NLL = mdnn.MixtureHead.nll


def matrix_form_nll(head: mdnn.MixtureHead, out: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    return mixture_nll(*head(out), theta)


def pairs(n: int, theta_dim: int, x_dim: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    theta = torch.rand(n, theta_dim, generator=g)
    a = torch.randn(theta_dim, x_dim, generator=g)
    return theta, theta @ a + 0.1 * torch.randn(n, x_dim, generator=g)


def timed_fit(name: str, cfg: dict, theta: torch.Tensor, x: torch.Tensor, device: str, graphed: bool,
              matrix_loss: bool = False, box: bool = False) -> float:
    # the eager row swaps the step factory: the same fit with one launch per kernel
    base.adam_steps = adam_steps.adam_steps if graphed else adam_steps.EagerAdamSteps
    mdnn.MixtureHead.nll = matrix_form_nll if matrix_loss else HEAD_NLL
    model = build("model", {"name": name, **cfg}, theta_dim=theta.shape[1], x_dim=x.shape[1])
    if box:  # pairs() draws theta in the unit box
        model.set_support(torch.zeros(theta.shape[1]), torch.ones(theta.shape[1]))
    theta, x = theta.to(device), x.to(device)
    if device == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    model.fit(theta, x, seed=0, label=name)
    return time.perf_counter() - start


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", nargs="+", default=["mdnn", "mdrff", "flow"])
    ap.add_argument("--sims", type=int, default=10000)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--theta-dim", type=int, default=2)
    ap.add_argument("--x-dim", type=int, default=6)
    ap.add_argument("--batch-size", type=int, default=256)
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="model config overrides (YAML values)")
    ap.add_argument("--threads", nargs="+", type=int, default=[torch.get_num_threads()])
    ap.add_argument("--box", action="store_true", help="mdnn: rows of the fit truncated to the parameters' box")
    args = ap.parse_args()
    overrides = {k: yaml.safe_load(v) for k, v in (item.split("=", 1) for item in args.set)}
    theta, x = pairs(args.sims, args.theta_dim, args.x_dim)
    # training steps only: the spread calibration after them (mixtures) is not an epoch's cost
    cfg = {**overrides, "max_epochs": args.epochs, "patience": args.epochs, "batch_size": args.batch_size,
           "calibrate": False}
    cap = base.CPU_TRAINING_THREADS
    variants = [(f"cpu, {n} threads" + (f" ({cap} train)" if n > cap else "") if len(args.threads) > 1 else "cpu",
                 "cpu", False, n) for n in args.threads]
    if torch.cuda.is_available():
        cpu_threads = args.threads[0]
        variants += [("cuda eager", "cuda", False, cpu_threads), ("cuda graph", "cuda", True, cpu_threads)]
    for name in args.models:  # one-time costs (imports, CUDA context, kernel loading) before timing
        for _, device, graphed, threads in variants:
            torch.set_num_threads(threads)
            timed_fit(name, {**cfg, "max_epochs": 1}, theta[:1000], x[:1000], device, graphed)
    print(f"{args.sims} pairs, theta {args.theta_dim}-D, x {args.x_dim}-D, batch {args.batch_size}, "
          f"{args.epochs} epochs, {overrides or 'defaults'}; torch {torch.__version__}, {os.cpu_count()} CPUs"
          + (f", {torch.cuda.get_device_name()}" if torch.cuda.is_available() else ""))
    print(f"{'model':<8} {'where':<26} {'s per epoch':>12} {'vs first':>8}")
    for name in args.models:
        baseline = None
        mixture = name in ("mdnn", "mdrff")
        for label, device, graphed, threads in variants:
            torch.set_num_threads(threads)
            # the loss by autograd: one row per device, not per thread count
            losses = [(False, False)] + [(True, False)] * (mixture and len(args.threads) == 1) \
                + [(False, True)] * (args.box and name == "mdnn")
            for matrix_loss, box in losses:
                per_epoch = timed_fit(name, cfg, theta, x, device, graphed, matrix_loss, box) / args.epochs
                baseline = baseline or per_epoch
                label_ = f"{label}, matrix loss" if matrix_loss else f"{label}, box-truncated" if box else label
                print(f"{name:<8} {label_:<26} {per_epoch:>12.4f} {baseline / per_epoch:>7.1f}x", flush=True)


if __name__ == "__main__":
    main()

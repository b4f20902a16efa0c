"""Adam steps over the batches of an epoch, eagerly on a CPU and replayed from a CUDA graph on a GPU.

A density network's step is many small kernels; launched one by one from Python they leave a GPU
idle most of the time (on the lent H100 machine an eager GPU epoch was slower than the CPU's).
Captured once into a CUDA graph, a step is one launch (a whole epoch in one graph measured slower,
docs/benchmarks.md). The graphed step reads its rows through a fixed index buffer, so every batch has the same size: the
last batch of an epoch is filled up with rows from the epoch's start.

Both keep the first non-finite loss or gradient on the device, read once per epoch: a read per step
would stall a GPU at every batch.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch

from ..errors import TrainingError
from .adam import Adam

log = logging.getLogger(__name__)

_WARMUP_STEPS = 3  # eager steps on a side stream before capture (CUDA graphs need warmed-up allocations)


class EagerAdamSteps:
    def __init__(self, net: torch.nn.Module, nll: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
                 theta: torch.Tensor, x: torch.Tensor, cfg, label: str, capturable: bool = False):
        dev = theta.device
        self.nll, self.theta, self.x, self.batch_size, self.label = nll, theta, x, cfg.batch_size, label
        self.params = [p for p in net.parameters() if p.requires_grad]
        # on a GPU the fused Adam: one kernel for every parameter's update instead of several per tensor
        self.opt = Adam(self.params, lr=cfg.lr, weight_decay=cfg.weight_decay, capturable=capturable)
        self.step = torch.zeros((), dtype=torch.long, device=dev)
        self.bad_loss_step = torch.full((), -1, dtype=torch.long, device=dev)
        self.bad_grad_step = torch.full((), -1, dtype=torch.long, device=dev)
        self.bad_loss = torch.zeros((), device=dev)
        self.total = torch.zeros((), device=dev)

    def _step(self, rows: torch.Tensor) -> None:
        """One Adam step on `rows`; every write goes into a tensor made beforehand (graph-safe)."""
        loss = self.nll(self.theta[rows], self.x[rows]).mean()
        loss.backward()
        self.step += 1
        first = (self.bad_loss_step < 0) & ~torch.isfinite(loss)
        self.bad_loss_step.copy_(torch.where(first, self.step, self.bad_loss_step))
        self.bad_loss.copy_(torch.where(first, loss.detach(), self.bad_loss))
        grad_norm = torch.nn.utils.get_total_norm([p.grad for p in self.params if p.grad is not None])
        grad_ok = torch.isfinite(grad_norm) | ~torch.isfinite(loss)
        self.bad_grad_step.copy_(torch.where((self.bad_grad_step < 0) & ~grad_ok, self.step, self.bad_grad_step))
        self.opt.step()
        self.total += loss.detach() * len(rows)

    def _batches(self, order: torch.Tensor) -> list[torch.Tensor]:
        return list(order.split(self.batch_size))

    def _run(self, rows: torch.Tensor) -> None:
        self.opt.zero_grad()
        self._step(rows)

    def epoch(self, order: torch.Tensor) -> float:
        """Steps over the rows in `order`; the mean training loss."""
        self.total.zero_()
        count = 0
        for rows in self._batches(order):
            self._run(rows)
            count += len(rows)
        return self.total.item() / count

    def raise_if_not_finite(self, epoch: int) -> None:
        if self.bad_loss_step >= 0:
            raise TrainingError(f"{self.label}: loss became {self.bad_loss.item()} at epoch {epoch}, "
                                f"step {int(self.bad_loss_step)}")
        if self.bad_grad_step >= 0:
            raise TrainingError(f"{self.label}: non-finite gradient at epoch {epoch}, step {int(self.bad_grad_step)}")


class GraphedAdamSteps(EagerAdamSteps):
    """The first steps run eagerly on a side stream, the next one is captured; all later ones replay it.
    A network whose step cannot be captured (an operation that reads back to the host) goes on eagerly."""

    def __init__(self, net, nll, theta, x, cfg, label):
        super().__init__(net, nll, theta, x, cfg, label, capturable=True)
        self.batch_size = min(cfg.batch_size, len(theta))
        self.rows = torch.zeros(self.batch_size, dtype=torch.long, device=theta.device)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.eager_steps = 0
        self.capture_failed = False

    def _batches(self, order: torch.Tensor) -> list[torch.Tensor]:
        short = -len(order) % self.batch_size
        return list(torch.cat([order, order[:short]]).split(self.batch_size))

    def _run(self, rows: torch.Tensor) -> None:
        self.rows.copy_(rows)
        if self.graph is not None:
            self.graph.replay()
        elif self.capture_failed:
            super()._run(self.rows)
        elif self.eager_steps < _WARMUP_STEPS:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                super()._run(self.rows)
            torch.cuda.current_stream().wait_stream(side)
            self.eager_steps += 1
        else:
            self._capture()
            if self.graph is not None:
                self.graph.replay()
            else:
                super()._run(self.rows)

    def _capture(self) -> None:
        self.opt.zero_grad()
        graph = torch.cuda.CUDAGraph()
        try:
            # thread_local: JAX's threads may call CUDA meanwhile; only this thread's calls must be capturable
            with torch.cuda.graph(graph, capture_error_mode="thread_local"):
                self._step(self.rows)
        except RuntimeError as exc:
            log.info("%s: the training step cannot be captured in a CUDA graph (%s); training eagerly",
                     self.label, str(exc).splitlines()[0])
            self.capture_failed = True
            return
        self.graph = graph


def adam_steps(net, nll, theta, x, cfg, label) -> EagerAdamSteps:
    cls = GraphedAdamSteps if theta.device.type == "cuda" else EagerAdamSteps
    return cls(net, nll, theta, x, cfg, label)

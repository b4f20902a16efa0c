"""Adam steps over the batches of an epoch, eagerly on a CPU and replayed from a CUDA graph on a GPU.

A density network's step is many small kernels; launched one by one from Python they leave a GPU
idle most of the time (on the lent H100 machine an eager GPU epoch was slower than the CPU's).
Captured once into a CUDA graph, a step is one launch (a whole epoch in one graph measured slower,
docs/benchmarks.md). The graphed step reads its rows through a fixed index buffer, so every batch has
the same size: the last batch of an epoch is filled up with rows from the epoch's start. The
validation loss gets a graph of its own.

Both keep every step's loss and gradient norms on the device and read them once per epoch, in one
transfer: each read waits for the GPU to finish its queue.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import torch

from ..errors import TrainingError
from .adam import Adam

log = logging.getLogger(__name__)

_WARMUP_STEPS = 3  # eager steps on a side stream before capture (CUDA graphs need warmed-up allocations)


class EagerAdamSteps:
    def __init__(self, net: torch.nn.Module, nll: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
                 theta: torch.Tensor, x: torch.Tensor, cfg, label: str, rows_per_epoch: int, capturable: bool = False):
        dev = theta.device
        self.nll, self.theta, self.x, self.batch_size, self.label = nll, theta, x, cfg.batch_size, label
        self.params = [p for p in net.parameters() if p.requires_grad]
        # on a GPU the fused Adam: one kernel for every parameter's update instead of several per tensor
        self.opt = Adam(self.params, lr=cfg.lr, weight_decay=cfg.weight_decay, capturable=capturable)
        self.steps_done = 0
        self.batch_rows: list[int] = []  # of the epoch's steps
        # each step of the epoch writes its loss and its gradients' norms into its row (read once per epoch;
        # testing them on the device would cost a dozen kernels a step)
        self.record = torch.zeros(math.ceil(rows_per_epoch / cfg.batch_size), 1 + len(self.params), device=dev)
        self.slot = torch.zeros(1, dtype=torch.long, device=dev)  # the row of the next step

    def _step(self, rows: torch.Tensor) -> None:
        """One Adam step on `rows`; every write goes into a tensor made beforehand (graph-safe)."""
        loss = self.nll(self.theta[rows], self.x[rows]).mean()
        loss.backward()
        norms = torch._foreach_norm([p.grad if p.grad is not None else p.new_zeros(()) for p in self.params])
        self.record.index_copy_(0, self.slot, torch.stack([loss.detach(), *norms])[None])
        self.slot += 1
        self.opt.step()

    def _batches(self, order: torch.Tensor) -> list[torch.Tensor]:
        return list(order.split(self.batch_size))

    def _run(self, rows: torch.Tensor) -> None:
        self.opt.zero_grad()
        self._step(rows)

    def epoch(self, order: torch.Tensor) -> None:
        """Steps over the rows in `order` (on a GPU only launched: finish_epoch reads the results)."""
        self.slot.zero_()
        self.batch_rows = []
        for rows in self._batches(order):
            self._run(rows)
            self.batch_rows.append(len(rows))

    @torch.no_grad()
    def validation_loss(self, rows: torch.Tensor) -> torch.Tensor:
        """The mean loss on `rows` (the same rows every epoch), left on the device."""
        return self.nll(self.theta[rows], self.x[rows]).mean()

    def finish_epoch(self, epoch: int, validation_loss: torch.Tensor) -> tuple[float, float]:
        """(mean training loss, validation loss) of the epoch, read in one transfer (each read waits for
        the GPU); raises TrainingError at the first non-finite loss or gradient."""
        values = torch.cat([validation_loss.reshape(1), self.record.flatten()]).tolist()
        val, width = values[0], self.record.shape[1]
        records = [values[1 + i * width:1 + (i + 1) * width] for i in range(len(self.batch_rows))]
        first_step = self.steps_done + 1
        self.steps_done += len(records)
        for i, (loss, *norms) in enumerate(records):
            if not all(map(math.isfinite, norms)) or not math.isfinite(loss):
                what = f"loss became {loss}" if not math.isfinite(loss) else "non-finite gradient"
                raise TrainingError(f"{self.label}: {what} at epoch {epoch}, step {first_step + i}")
        return sum(r[0] * n for r, n in zip(records, self.batch_rows)) / sum(self.batch_rows), val


class GraphedAdamSteps(EagerAdamSteps):
    """The first steps run eagerly on a side stream, the next one is captured; all later ones replay it.
    A network whose step cannot be captured (an operation that reads back to the host) goes on eagerly."""

    def __init__(self, net, nll, theta, x, cfg, label, rows_per_epoch):
        super().__init__(net, nll, theta, x, cfg, label, rows_per_epoch, capturable=True)
        self.batch_size = min(cfg.batch_size, len(theta))
        self.rows = torch.zeros(self.batch_size, dtype=torch.long, device=theta.device)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.eager_steps = 0
        self.capture_failed = False
        self.validation_graph: torch.cuda.CUDAGraph | None = None
        self.validation_out: torch.Tensor | None = None
        self.eager_validations = 0

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
        self.graph = self._captured(lambda: self._step(self.rows), "training step")
        self.capture_failed = self.graph is None

    def validation_loss(self, rows: torch.Tensor) -> torch.Tensor:
        """Replayed from a graph of its own once the training step is captured (an eager forward pass
        each epoch is dozens of launches with the GPU idle); `rows` must be the same tensor every epoch."""
        if self.validation_graph is None and self.graph is not None and self.eager_validations == _WARMUP_STEPS:
            def forward() -> None:
                self.validation_out = EagerAdamSteps.validation_loss(self, rows)

            self.validation_graph = self._captured(forward, "validation loss")
        if self.validation_graph is None:
            self.eager_validations += 1  # past the warm-up without a graph: eager for good
            return super().validation_loss(rows)
        self.validation_graph.replay()
        return self.validation_out

    def _captured(self, work: Callable[[], None], what: str) -> torch.cuda.CUDAGraph | None:
        graph = torch.cuda.CUDAGraph()
        try:
            # thread_local: JAX's threads may call CUDA meanwhile; only this thread's calls must be capturable
            with torch.cuda.graph(graph, capture_error_mode="thread_local"):
                work()
        except RuntimeError as exc:
            log.info("%s: the %s cannot be captured in a CUDA graph (%s); running it eagerly",
                     self.label, what, str(exc).splitlines()[0])
            return None
        return graph


def adam_steps(net, nll, theta, x, cfg, label, rows_per_epoch: int) -> EagerAdamSteps:
    if theta.device.type == "cuda":
        return GraphedAdamSteps(net, nll, theta, x, cfg, label, rows_per_epoch)
    return EagerAdamSteps(net, nll, theta, x, cfg, label, rows_per_epoch)

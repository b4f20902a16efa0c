"""TensorBoard writer for a run: scalars, loss curves, posterior figures and the config text; `NO_TENSORBOARD` writes
nothing, for stages run or read outside a run.

Figures are drawn by a separate process (logging/plots.py, as PNG): importing matplotlib and drawing
took 2.5-3 s of the default run's stages on the H100 machine, which the run's own process now spends
on its stages. A drawing thread gained nothing (measured, docs/benchmarks.md), presumably as it
takes the GIL from the stages' many short torch calls. The figures' data (posterior draws included)
is taken in the run's process, so its random streams do not depend on the drawing. close() waits for
every figure; one that fails is reported and left out, never failing the run.

A process that may run on one CPU only (a pinned test worker, a one-core Slurm job) draws in its own process: the
drawing process would gain nothing there, and its start (a fresh interpreter importing torch and matplotlib) costs
more CPU time than the figures themselves (docs/benchmarks.md).

A spawned process imports the caller's `__main__` again: a user's script that calls api.run without a main guard
would run again in it (a second run into the same directory, then a crash). So api.run draws in its own process
(`drawing_process=False`), as does any run from the moment its drawing process ends.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import logging
import multiprocessing
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np

from ..machine import usable_cpus
from ..quick_exit import exit_without_finalization

log = logging.getLogger(__name__)


def _drawing_process_setup() -> None:
    """The drawing process has nothing to write at its end; close() waits for it to end."""
    atexit.register(exit_without_finalization)


def _warm_up() -> None:
    """In the drawing process, while the run's first stages go on."""
    from . import plots  # noqa: F401


def _png(name: str, *args) -> bytes:
    """In the drawing process: logging/plots.py's figure `name`, as PNG bytes."""
    from . import plots

    figure = getattr(plots, name)(*args)
    out = io.BytesIO()
    figure.savefig(out, format="png")
    plots.plt.close(figure)
    return out.getvalue()


@contextlib.contextmanager
def _interpreter_start_method():
    """A process spawned from a joblib worker (hydra/launcher=local) is told to set up the worker's start
    method, 'loky', which a fresh interpreter does not know: it dies before running anything. The drawing
    process is started under the interpreter's own default instead."""
    method = multiprocessing.get_start_method(allow_none=True)
    if method in (None, *multiprocessing.get_all_start_methods()):
        yield
        return
    multiprocessing.set_start_method(None, force=True)
    try:
        yield
    finally:
        multiprocessing.set_start_method(method, force=True)


class _InProcess:
    """The drawing done where it is asked for, behind the executor's submit / shutdown."""

    def submit(self, fn, *args) -> Future:
        future: Future = Future()
        try:
            future.set_result(fn(*args))
        except Exception as exc:  # noqa: BLE001 - reported where the figure is written, as from the process
            future.set_exception(exc)
        return future

    def shutdown(self) -> None:
        pass


class TensorBoardLogger:
    def __init__(self, log_dir: str | Path, drawing_process: bool = True, figures: bool = True):
        """figures=False (logging.figures): none drawn; their data are still taken, so the run's random streams and
        results are those of a run that draws them."""
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(log_dir))
        self._drawing: ProcessPoolExecutor | _InProcess = _InProcess()
        self.figures = figures
        # on one CPU a second process draws nothing sooner, and starting it costs more than the drawing itself
        if figures and drawing_process and usable_cpus() > 1:
            # spawn: a forked copy of a process that holds CUDA and JAX state is not safe
            with _interpreter_start_method():  # the process starts at the first submit
                self._drawing = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                                                    initializer=_drawing_process_setup)
                self._drawing.submit(_warm_up)
        self._pending: list[tuple[str, int, Future]] = []  # figures being drawn, in the order asked for

    def _figure(self, tag: str, step: int, name: str, *args) -> None:
        if not self.figures:
            return
        try:
            self._pending.append((tag, step, self._drawing.submit(_png, name, *args)))
        except BrokenProcessPool as exc:  # the drawing process died: the figures are drawn here from now on
            log.warning("TensorBoard figures are drawn in the run's process from round %d on: the drawing process "
                        "ended (%s)", step, exc)
            self._drawing = _InProcess()
            self._pending.append((tag, step, self._drawing.submit(_png, name, *args)))
        self._add_drawn()

    def _add_drawn(self, wait: bool = False) -> None:
        """Writes the figures drawn so far (all of them, waiting, with wait=True)."""
        while self._pending and (wait or self._pending[0][2].done()):
            tag, step, future = self._pending.pop(0)
            try:
                self.image(tag, future.result(), step)
            except Exception as exc:  # noqa: BLE001 - a figure is not worth a run
                log.warning("TensorBoard figure %s of round %d could not be drawn: %r", tag, step, exc)

    def config(self, yaml_text: str) -> None:
        # four-space indent renders as a code block in TensorBoard's text tab
        self.writer.add_text("config", "\n".join("    " + line for line in yaml_text.splitlines()), 0)

    def losses(self, round_index: int, history: dict) -> None:
        """One round's training curve, under its own tag so rounds overlay on the epoch axis."""
        for k, (train, val) in enumerate(zip(history["train"], history["val"])):
            self.writer.add_scalar(f"loss/round_{round_index}/train", train, k)
            self.writer.add_scalar(f"loss/round_{round_index}/val", val, k)
        self.writer.add_scalar("loss/best_val_per_round", history["best_val"], round_index)

    def scalar(self, tag: str, value: float, step: int) -> None:
        self.writer.add_scalar(tag, value, step)

    def scalars(self, round_index: int, values: dict[str, float]) -> None:
        self._add_drawn()
        for tag, v in values.items():
            if v is not None and np.isfinite(v):
                self.writer.add_scalar(tag, v, round_index)

    def posterior(self, round_index: int, posterior, prior, names: list[str], plot_names: list[str],
                  true: np.ndarray | None, num_samples: int, low: np.ndarray, high: np.ndarray, title: str,
                  flat: bool = False) -> None:
        """Pair plot of draws of what the round handed on over prior draws, titled `title`; low/high: the
        parameters' ranges (the axes); `flat`: the distribution is uniform on them."""
        idx = [names.index(n) for n in plot_names]
        samples = posterior.sample((num_samples,)).numpy()[:, idx]
        prior_samples = prior.sample((num_samples,)).numpy()[:, idx]
        self._figure("posterior", round_index, "pair_plot", samples, plot_names, np.asarray(low)[idx],
                     np.asarray(high)[idx], None if true is None else true[idx], title, prior_samples, flat)

    def identifiability(self, round_index: int, names: list[str], report: dict) -> None:
        """The identifiability report (diagnostics/identifiability.py) as bars per parameter."""
        local = report["local"]
        self._figure("identifiability", round_index, "identifiability_plot", names, [report["r2"][n] for n in names],
                     None if local is None else [local["rms"][n] for n in names], f"round {round_index}")

    def image(self, tag: str, encoded: bytes, step: int) -> None:
        """An encoded image (PNG; an animated GIF, which TensorBoard's IMAGES tab plays, without moviepy)
        as an image summary, as it is."""
        from PIL import Image
        from tensorboard.compat.proto.summary_pb2 import Summary

        width, height = Image.open(io.BytesIO(encoded)).size
        image = Summary.Image(height=height, width=width, colorspace=3, encoded_image_string=encoded)
        self.writer._get_file_writer().add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), step)
        self.writer.flush()

    def replays(self, round_index: int, check, obs_names: list[str], max_trajectories: int = 3) -> None:
        """The replayed predictive check (diagnostics/replayed_check.py) as a picture."""
        k = min(max_trajectories, check.real.num)
        self._figure("predictive/replay", round_index, "replay_plot", check.real.states[:k].numpy(),
                     check.posterior_states[:k].numpy(), check.prior_states[:k].numpy(), obs_names, check.real.dt,
                     list(check.p_value[:k]), f"replayed predictive check, round {round_index}")

    def close(self) -> None:
        """Waits for the figures, then closes the drawing process and the event file."""
        self._add_drawn(wait=True)
        self._drawing.shutdown()
        self.writer.close()


def _nothing(*args, **kwargs) -> None:
    return None


class NullTensorBoard:
    """Every public method of TensorBoardLogger, read from it (so the two cannot drift apart), writing nothing and
    taking no draws (a run's scored rounds want the logger's posterior draws in their random streams: a Pipeline
    always has one)."""

    def __getattr__(self, name: str):
        if name.startswith("_") or not callable(getattr(TensorBoardLogger, name, None)):
            raise AttributeError(f"{type(self).__name__} has no {name!r}: TensorBoardLogger has no such method")
        return _nothing


NO_TENSORBOARD = NullTensorBoard()

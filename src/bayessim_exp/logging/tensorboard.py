"""TensorBoard writer for a run: scalars, loss curves, posterior figures and the config text."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np


class TensorBoardLogger:
    def __init__(self, log_dir: str | Path):
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(log_dir))

    def config(self, yaml_text: str) -> None:
        # four-space indent renders as a code block in TensorBoard's text tab
        self.writer.add_text("config", "\n".join("    " + line for line in yaml_text.splitlines()), 0)

    def losses(self, round_index: int, history: dict) -> None:
        """One round's training curve, under its own tag so rounds overlay on the epoch axis."""
        for k, (train, val) in enumerate(zip(history["train"], history["val"])):
            self.writer.add_scalar(f"loss/round_{round_index}/train", train, k)
            self.writer.add_scalar(f"loss/round_{round_index}/val", val, k)
        self.writer.add_scalar("loss/best_val_per_round", history["best_val"], round_index)

    def scalars(self, round_index: int, values: dict[str, float]) -> None:
        for tag, v in values.items():
            if v is not None and np.isfinite(v):
                self.writer.add_scalar(tag, v, round_index)

    def posterior(self, round_index: int, posterior, prior, names: list[str], plot_names: list[str],
                  true: np.ndarray | None, num_samples: int, low: np.ndarray, high: np.ndarray) -> None:
        """Pair plot of posterior draws over prior draws; low/high: the parameters' ranges (the axes)."""
        from .plots import pair_plot

        idx = [names.index(n) for n in plot_names]
        samples = posterior.sample((num_samples,)).numpy()[:, idx]
        prior_samples = prior.sample((num_samples,)).numpy()[:, idx]
        fig = pair_plot(samples, plot_names, np.asarray(low)[idx], np.asarray(high)[idx], None if true is None else true[idx],
                        f"posterior, round {round_index}", prior_samples)
        self.writer.add_figure("posterior", fig, round_index)
        self.writer.flush()

    def gif(self, tag: str, gif_bytes: bytes, step: int) -> None:
        """An animated GIF as an image summary (TensorBoard's IMAGES tab plays it), without moviepy."""
        from PIL import Image
        from tensorboard.compat.proto.summary_pb2 import Summary

        width, height = Image.open(io.BytesIO(gif_bytes)).size
        image = Summary.Image(height=height, width=width, colorspace=3, encoded_image_string=gif_bytes)
        self.writer._get_file_writer().add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), step)
        self.writer.flush()

    def replays(self, round_index: int, check, obs_names: list[str], max_trajectories: int = 3) -> None:
        """The replayed predictive check (diagnostics/replayed_check.py) as a picture."""
        from .plots import replay_plot

        k = min(max_trajectories, check.real.num)
        fig = replay_plot(check.real.states[:k].numpy(), check.posterior_states[:k].numpy(),
                          check.prior_states[:k].numpy(), obs_names, check.real.dt, check.p_value[:k],
                          f"replayed predictive check, round {round_index}")
        self.writer.add_figure("predictive/replay", fig, round_index)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()

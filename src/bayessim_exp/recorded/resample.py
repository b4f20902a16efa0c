"""A log's own time stamps -> the task's control steps.

States are samples of continuous signals: they are interpolated linearly at the control times. Actions are
commands a controller held until its next command (a zero-order hold): each control step takes the time
average of that held signal over the step, so a faster log's commands are averaged (a torque delivers the
same impulse over the step) and a command spanning several steps is held; interpolating them instead would
invent commands the actuators never received. A log slower than the control rate, or with a gap longer than a
control step, is refused: the states in between would be guesses that the summaries then read as dynamics.
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError

# a frame step this much longer than the control step is still resampled: a robot's clock jitters, and
# interpolating over a step 5 % longer than the control step invents nothing the summaries would read
JITTER = 0.05
# the share of a control step by which the log may end short of the last control time: float32 time stamps
ROUNDING = 1e-3


def control_times(times: np.ndarray, dt: float, where: str) -> np.ndarray:
    """The control times t0, t0 + dt, ... that the log covers, after checking that it can be resampled to them."""
    if len(times) < 2:
        raise DataError(f"{where}: {len(times)} frame(s); an episode needs at least two")
    unknown = np.flatnonzero(~np.isfinite(times))
    if unknown.size:
        raise DataError(f"{where}: the time stamp at row {unknown[0]} is {times[unknown[0]]}; drop or fill that frame")
    steps = np.diff(times)
    back = np.flatnonzero(steps <= 0)
    if back.size:
        row = int(back[0]) + 1
        raise DataError(f"{where}: time does not increase at row {row} ({times[row - 1]:g} s, then {times[row]:g} s); "
                        "sort the rows by time and drop repeated frames")
    typical = float(np.median(steps))
    if typical > dt * (1 + JITTER):
        raise DataError(f"{where}: recorded every {typical:g} s ({1 / typical:g} Hz), slower than the task's control "
                        f"step {dt:g} s ({1 / dt:g} Hz): the states between frames cannot be resampled; record at "
                        f"{1 / dt:g} Hz or faster, or run with a task.control_dt the log covers")
    gap = int(np.argmax(steps))
    if steps[gap] > dt * (1 + JITTER):
        raise DataError(f"{where}: time jumps by {steps[gap]:g} s at row {gap + 1} ({times[gap]:g} s to "
                        f"{times[gap + 1]:g} s), longer than the control step {dt:g} s: frames are missing there; "
                        "cut the episode at the gap or leave it out")
    count = int(np.floor((times[-1] - times[0]) / dt + ROUNDING))
    return times[0] + dt * np.arange(count + 1)


def interpolate(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """values [N] sampled at times -> [len(grid)], linear in between."""
    return np.interp(grid, times, values)


def hold_average(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Commands values [N] held from times[i] to times[i + 1] -> their mean over each [grid[k], grid[k + 1]):
    [len(grid) - 1]. The held signal's integral is piecewise linear between the time stamps, so interpolating it
    is exact, whatever the ratio of the two rates."""
    integral = np.concatenate([[0.0], np.cumsum(values[:-1] * np.diff(times))])
    return np.diff(np.interp(grid, times, integral)) / np.diff(grid)

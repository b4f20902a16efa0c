"""A pendulum written independently of the project's MJCF: the ODE integrated finely with RK4.

Stands in for a robot's logs in the real-data tests and in benchmarks/real_data.py. Conventions
are those docs/tasks.md states for Pendulum: angle 0 upright, positive rotation and torque in the
same sense, gravity pushing away from upright, actions in [-1, 1] scaled to a 2 N m torque range.

    rod:  I theta'' = m g (L/2) sin(theta) + u - b theta',   I = m L^2 / 3
    bob:  I theta'' = m g L sin(theta) + u - b theta',       I = m L^2       (a point mass at L)
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import minimize

from bayessim_exp.diagnostics.replay import replay

GRAVITY = 9.81
TORQUE_RANGE = 2.0
CONTROL_DT = 0.05


def simulate(mass: float, length: float, n: int, horizon: int, seed: int, *, damping: float = 0.0,
             shape: str = "rod", substeps: int = 50, angle_offset: float = 0.0) -> dict[str, np.ndarray]:
    """n trajectories of `horizon` control steps in the npz layout of real=file.

    Initial states and actions are drawn as the collect policy draws them (theta ~ U(-pi, pi),
    theta' ~ U(-1, 1), actions ~ U(-1, 1)). angle_offset adds a constant to the logged angle (a log
    that measures the angle from another zero)."""
    if shape == "rod":
        lever, inertia = length / 2, mass * length**2 / 3
    elif shape == "bob":
        lever, inertia = length, mass * length**2
    else:
        raise ValueError(shape)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, n)
    omega = rng.uniform(-1.0, 1.0, n)
    actions = rng.uniform(-1.0, 1.0, (n, horizon, 1))
    h = CONTROL_DT / substeps

    def accel(th, om, torque):
        return (mass * GRAVITY * lever * np.sin(th) + torque - damping * om) / inertia

    states = np.empty((n, horizon + 1, 3))
    states[:, 0] = _observe(theta + angle_offset, omega)
    for t in range(horizon):
        torque = TORQUE_RANGE * actions[:, t, 0]
        for _ in range(substeps):  # classic RK4 on (theta, omega)
            k1t, k1o = omega, accel(theta, omega, torque)
            k2t, k2o = omega + h / 2 * k1o, accel(theta + h / 2 * k1t, omega + h / 2 * k1o, torque)
            k3t, k3o = omega + h / 2 * k2o, accel(theta + h / 2 * k2t, omega + h / 2 * k2o, torque)
            k4t, k4o = omega + h * k3o, accel(theta + h * k3t, omega + h * k3o, torque)
            theta = theta + h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
            omega = omega + h / 6 * (k1o + 2 * k2o + 2 * k3o + k4o)
        states[:, t + 1] = _observe(theta + angle_offset, omega)
    return {"states": states, "actions": actions, "dt": np.array(CONTROL_DT),
            "params": np.array([mass, length]), "param_names": np.array(["mass", "length"])}


def _observe(theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(theta), np.sin(theta), omega], -1)


def best_fit(sims, real, steps: int) -> np.ndarray:
    """The least-squares fit of our model: the parameters inside the prior box whose replays (recorded
    initial states, recorded actions) of the first `steps` steps are closest to the recorded states
    (a 41 x 41 grid, then Nelder-Mead)."""
    real = real.truncate(steps)
    n = real.num

    def cost(theta: torch.Tensor) -> torch.Tensor:
        which = torch.arange(n).repeat(len(theta))
        out = replay(sims, theta.repeat_interleave(n, 0), real, which).states.double()
        return (out - real.states.double()[which]).reshape(len(theta), -1).pow(2).sum(1)

    low, high = sims.task.spec.low, sims.task.spec.high
    axes = [torch.linspace(lo, hi, 41, dtype=torch.float64) for lo, hi in zip(low, high)]
    grid = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))
    start = grid[cost(grid).argmin()].numpy()
    res = minimize(lambda t: float(cost(torch.as_tensor(t)[None])), start, method="Nelder-Mead",
                   bounds=list(zip(low, high)), options={"xatol": 1e-5, "fatol": 1e-10})
    return res.x


def hpd_level(post, theta: np.ndarray, draws: int = 4000) -> float:
    """The smallest highest-density region of `post` holding theta: inside the 90 % region iff < 0.9."""
    t = torch.as_tensor(theta, dtype=torch.float64)[None]
    with torch.random.fork_rng():
        torch.manual_seed(1)
        lp = post.log_prob(post.sample((draws,)).double())
    return float((lp > post.log_prob(t)).double().mean())

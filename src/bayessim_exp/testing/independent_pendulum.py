"""A pendulum written independently of the project's MJCF: the ODE integrated by other integrators.

Stands in for a robot's logs in the real-data tests and in benchmarks/foreign_dynamics.py. Conventions
are those docs/tasks.md states for Pendulum: angle 0 upright, positive rotation and torque in the
same sense, gravity pushing away from upright, actions in [-1, 1] scaled to a 2 N m torque range.

    rod:  I theta'' = m g (L/2) sin(theta) + tau - b theta' - c sign(theta'),   I = m L^2 / 3
    bob:  I theta'' = m g L sin(theta) + tau - b theta' - c sign(theta'),       I = m L^2  (a point mass at L)
    motor: tau = 2 N m * action, or with a lag T: tau' = (2 N m * action - tau) / T

Our model (MuJoCo, implicit-fast at 0.01 s) is the rod with b = c = 0 and no lag; integrators and
time steps differ here: classic RK4 (`rk4`, 50 substeps per 0.05 s control step), semi-implicit Euler
at a fifth of our time step (`euler`), and SciPy's adaptive Dormand-Prince (`scipy`, rtol 1e-9).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from ..diagnostics.replay import replay

GRAVITY = 9.81
TORQUE_RANGE = 2.0
CONTROL_DT = 0.05
INTEGRATORS = ("rk4", "euler", "scipy")
EXCITATIONS = ("random", "sine")


def excitation(kind: str, n: int, horizon: int, rng: np.random.Generator) -> np.ndarray:
    """Actions [n, horizon, 1]: uniform random, as the collect policy draws them, or a sine per trajectory
    (amplitude 0.6-1, 0.3-1.5 Hz, random phase), as an excitation experiment on a robot would."""
    if kind == "random":
        return rng.uniform(-1.0, 1.0, (n, horizon, 1))
    if kind != "sine":
        raise ValueError(kind)
    t = np.arange(horizon) * CONTROL_DT
    amplitude, freq, phase = rng.uniform(0.6, 1.0, (n, 1)), rng.uniform(0.3, 1.5, (n, 1)), rng.uniform(0, 2 * np.pi, (n, 1))
    return (amplitude * np.sin(2 * np.pi * freq * t + phase))[..., None]


def simulate(mass: float, length: float, n: int, horizon: int, seed: int, *, damping: float = 0.0,
             friction: float = 0.0, motor_lag: float = 0.0, shape: str = "rod", integrator: str = "rk4",
             substeps: int = 50, angle_offset: float = 0.0, actions: str = "random") -> dict[str, np.ndarray]:
    """n trajectories of `horizon` control steps in the npz layout of real=file.

    Initial states are drawn as the task's reset draws them (theta ~ U(-pi, pi), theta' ~ U(-1, 1)),
    actions by `excitation`. angle_offset adds a constant to the logged angle (a log that measures the
    angle from another zero)."""
    if shape == "rod":
        lever, inertia = length / 2, mass * length**2 / 3
    elif shape == "bob":
        lever, inertia = length, mass * length**2
    else:
        raise ValueError(shape)
    if integrator not in INTEGRATORS:
        raise ValueError(integrator)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, n)
    omega = rng.uniform(-1.0, 1.0, n)
    acts = excitation(actions, n, horizon, rng)
    torque = np.zeros(n)

    def derivative(th, om, tq, command):
        accel = (mass * GRAVITY * lever * np.sin(th) + tq - damping * om - friction * np.tanh(om / 1e-2)) / inertia
        return om, accel, (command - tq) / motor_lag if motor_lag else np.zeros_like(tq)

    states = np.empty((n, horizon + 1, 3))
    states[:, 0] = _observe(theta + angle_offset, omega)
    for t in range(horizon):
        command = TORQUE_RANGE * acts[:, t, 0]
        if not motor_lag:
            torque = command
        theta, omega, torque = _advance(derivative, theta, omega, torque, command, integrator, substeps)
        states[:, t + 1] = _observe(theta + angle_offset, omega)
    return {"states": states, "actions": acts, "dt": np.array(CONTROL_DT),
            "params": np.array([mass, length]), "param_names": np.array(["mass", "length"])}


def _advance(derivative, theta, omega, torque, command, integrator: str, substeps: int):
    """One control step of (theta, omega, torque) under a held command."""
    if integrator == "scipy":
        n = len(theta)

        def rhs(_, y):
            return np.concatenate(derivative(y[:n], y[n : 2 * n], y[2 * n :], command))

        y = solve_ivp(rhs, (0.0, CONTROL_DT), np.concatenate([theta, omega, torque]), method="DOP853",
                      rtol=1e-9, atol=1e-9).y[:, -1]
        return y[:n], y[n : 2 * n], y[2 * n :]
    if integrator == "euler":  # semi-implicit: velocity first, at a fifth of our 0.01 s time step
        h = CONTROL_DT / 25
        for _ in range(25):
            _, accel, dtorque = derivative(theta, omega, torque, command)
            omega = omega + h * accel
            theta, torque = theta + h * omega, torque + h * dtorque
        return theta, omega, torque
    h = CONTROL_DT / substeps
    for _ in range(substeps):  # classic RK4
        k1 = derivative(theta, omega, torque, command)
        k2 = derivative(*(v + h / 2 * k for v, k in zip((theta, omega, torque), k1)), command)
        k3 = derivative(*(v + h / 2 * k for v, k in zip((theta, omega, torque), k2)), command)
        k4 = derivative(*(v + h * k for v, k in zip((theta, omega, torque), k3)), command)
        theta, omega, torque = (v + h / 6 * (a + 2 * b + 2 * c + d)
                                for v, a, b, c, d in zip((theta, omega, torque), k1, k2, k3, k4))
    return theta, omega, torque


def _observe(theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(theta), np.sin(theta), omega], -1)


def best_fit(sims, real, steps: int) -> np.ndarray:
    """The least-squares fit of our model: the parameters inside the prior box whose replays (recorded
    initial states, recorded actions) of the first `steps` steps are closest to the recorded states
    (a 41 x 41 grid, then Nelder-Mead)."""
    return best_fits(sims, real, steps, [real.num])[0]


def best_fits(sims, real, steps: int, counts: list[int]) -> list[np.ndarray]:
    """best_fit of the first n recorded trajectories for each n in `counts`: the grid is replayed once, for the
    most of them, as a trajectory's squared distances do not depend on the others."""
    real = real.truncate(steps)

    def distances(theta: torch.Tensor, n: int) -> torch.Tensor:
        """Squared distance of each trajectory's replay at each theta [T, D] from the recording: [T, n]."""
        which = torch.arange(n).repeat(len(theta))
        out = replay(sims, theta.repeat_interleave(n, 0), real, which).states.cpu().double()  # MJX: on the GPU
        return (out - real.states.double()[which]).reshape(len(theta), n, -1).pow(2).sum(2)

    low, high = sims.task.spec.low, sims.task.spec.high
    axes = [torch.linspace(lo, hi, 41, dtype=torch.float64) for lo, hi in zip(low, high)]
    grid = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))
    on_grid = distances(grid, max(counts)).cumsum(1)
    fits = []
    for n in counts:
        start = grid[on_grid[:, n - 1].argmin()].numpy()
        res = minimize(lambda t, n=n: float(distances(torch.as_tensor(t)[None], n).sum()), start,
                       method="Nelder-Mead", bounds=list(zip(low, high)), options={"xatol": 1e-5, "fatol": 1e-10})
        fits.append(res.x)
    return fits


def hpd_level(post, theta: np.ndarray, draws: int = 4000) -> float:
    """The smallest highest-density region of `post` holding theta: inside the 90 % region iff < 0.9."""
    t = torch.as_tensor(theta, dtype=torch.float64)[None]
    with torch.random.fork_rng():
        torch.manual_seed(1)
        lp = post.log_prob(post.sample((draws,)).double())
    return float((lp > post.log_prob(t)).double().mean())

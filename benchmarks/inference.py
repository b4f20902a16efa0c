"""Inference benchmark: fit time and accuracy of mdnn, mdrff, flow and sbi's NPE with an MDN,
trained on the same simulations of two simulators whose posteriors are known.

    OMP_NUM_THREADS=1 PYTHONPATH=src python3 benchmarks/inference.py [--sims 5000] [--obs 10]

- linear_gaussian: x = A theta + b + N(0, 0.1^2 I), theta in R^3 with a Gaussian prior, x in R^5;
  the posterior is Gaussian in closed form.
- bimodal: theta ~ U[-2, 2]^2, x = (theta1^2, theta2 + theta1^2 / 2, theta1 theta2) + N(0, 0.1^2 I);
  the posterior has two modes (theta and -theta); reference by a 400 x 400 grid.

Accuracy is KL(reference || model posterior) = E_ref[log p_ref - log q] over 2000 reference draws
per observation, averaged over `--obs` observations from the prior (lower is better, 0 is exact);
each posterior is restricted to the prior's support as the pipeline does. Fit time is the wall time
of training only, on one thread. Every method uses its own default configuration (ours: the
conf/model YAMLs; sbi: NPE(density_estimator="mdn") defaults). sbi is an optional extra
(pip install bayessim_exp[sbi]); without it its rows are skipped.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

import bayessim_exp
from bayessim_exp.distributions.independent import BoxUniform, GaussianPrior
from bayessim_exp.inference.bayessim.correction import posterior
from bayessim_exp.registry import build

REF_DRAWS = 2000
CONF_MODEL_DIR = Path(bayessim_exp.__file__).parent / "conf" / "model"


class LinearGaussianTask:
    name = "linear_gaussian"

    def __init__(self):
        g = torch.Generator().manual_seed(0)
        self.A = torch.randn(5, 3, generator=g, dtype=torch.float64)
        self.b = torch.randn(5, generator=g, dtype=torch.float64)
        self.noise = 0.1
        self.prior = GaussianPrior(torch.zeros(3), torch.ones(3))
        self.sbi_prior = torch.distributions.MultivariateNormal(torch.zeros(3), torch.eye(3))

    def simulate(self, theta: torch.Tensor, g: torch.Generator) -> torch.Tensor:
        return theta @ self.A.T + self.b + self.noise * torch.randn(theta.shape[0], 5, generator=g, dtype=torch.float64)

    def reference(self, x: torch.Tensor):
        prec = torch.eye(3, dtype=torch.float64) + self.A.T @ self.A / self.noise**2
        cov = torch.linalg.inv(prec)
        mean = cov @ self.A.T @ (x - self.b) / self.noise**2
        return torch.distributions.MultivariateNormal(mean, cov)


class GridPosterior:
    """A 2-D posterior normalised on a grid; draws are grid cells jittered uniformly within the cell."""

    def __init__(self, log_unnorm, low: float, high: float, n: int = 400):
        self.log_unnorm, self.low, self.cell = log_unnorm, low, (high - low) / n
        centres = low + self.cell * (torch.arange(n, dtype=torch.float64) + 0.5)
        grid = torch.stack(torch.meshgrid(centres, centres, indexing="ij"), -1).reshape(-1, 2)
        lp = log_unnorm(grid)
        self.log_norm = float(torch.logsumexp(lp, 0) + 2 * math.log(self.cell))
        self.grid, self.weights = grid, torch.softmax(lp, 0)

    def sample(self, shape):
        idx = torch.multinomial(self.weights, math.prod(shape), replacement=True)
        jitter = (torch.rand(len(idx), 2, dtype=torch.float64) - 0.5) * self.cell
        return self.grid[idx] + jitter

    def log_prob(self, theta):
        return self.log_unnorm(theta) - self.log_norm


class BimodalTask:
    name = "bimodal"

    def __init__(self):
        self.noise = 0.1
        low, high = -2.0 * torch.ones(2, dtype=torch.float64), 2.0 * torch.ones(2, dtype=torch.float64)
        self.prior = BoxUniform(low, high)
        self.sbi_prior = None  # built on demand (needs sbi)

    @staticmethod
    def _f(theta: torch.Tensor) -> torch.Tensor:
        t1, t2 = theta[..., 0], theta[..., 1]
        return torch.stack([t1**2, t2 + t1**2 / 2, t1 * t2], -1)

    def simulate(self, theta: torch.Tensor, g: torch.Generator) -> torch.Tensor:
        return self._f(theta) + self.noise * torch.randn(theta.shape[0], 3, generator=g, dtype=torch.float64)

    def reference(self, x: torch.Tensor) -> GridPosterior:
        def log_unnorm(theta):
            return -0.5 * ((self._f(theta) - x) ** 2).sum(-1) / self.noise**2
        return GridPosterior(log_unnorm, -2.0, 2.0)


def _model_config(name: str) -> dict:
    return OmegaConf.to_container(OmegaConf.load(CONF_MODEL_DIR / f"{name}.yaml"))


def fit_ours(name: str, theta, x, task, seed: int):
    model = build("model", _model_config(name), theta_dim=theta.shape[1], x_dim=x.shape[1])
    start = time.perf_counter()
    history = model.fit(theta, x, seed=seed, label=f"{task.name} {name}")
    seconds = time.perf_counter() - start
    return seconds, history["epochs"], lambda x_o: posterior([model.conditional(x_o)], task.prior, task.prior, seed=seed)


def fit_sbi(theta, x, task, seed: int):
    from sbi.inference import NPE
    from sbi.utils import BoxUniform as SbiBoxUniform

    prior = task.sbi_prior or SbiBoxUniform(task.prior.low.float(), task.prior.high.float())
    torch.manual_seed(seed)
    inference = NPE(prior=prior, density_estimator="mdn", show_progress_bars=False)
    inference.append_simulations(theta.float(), x.float())
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # sbi prints its convergence message
        estimator = inference.train()
    seconds = time.perf_counter() - start
    post = inference.build_posterior(estimator)
    epochs = inference.summary["epochs_trained"][-1]

    class _Conditioned:
        def __init__(self, x_o):
            self.x_o = x_o.float()

        def log_prob(self, theta):
            return post.log_prob(theta.float(), x=self.x_o).double()

    return seconds, epochs, _Conditioned


def kl_from_reference(reference, approx, seed: int) -> float:
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        draws = reference.sample((REF_DRAWS,)).double()
    return float((reference.log_prob(draws) - approx.log_prob(draws)).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sims", type=int, default=5000, help="training simulations per simulator")
    parser.add_argument("--obs", type=int, default=10, help="held-out observations per simulator")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    try:
        import sbi  # noqa: F401
        methods = ["mdnn", "mdrff", "flow", "sbi NPE-MDN"]
    except ImportError:
        methods = ["mdnn", "mdrff", "flow"]
    rows = []
    for task in (LinearGaussianTask(), BimodalTask()):
        g = torch.Generator().manual_seed(args.seed)
        with torch.random.fork_rng():
            torch.manual_seed(args.seed)
            theta = task.prior.sample((args.sims + args.obs,)).double()
        x = task.simulate(theta, g)
        theta_train, x_train, x_obs = theta[: args.sims], x[: args.sims], x[args.sims :]
        for method in methods:
            if method.startswith("sbi"):
                seconds, epochs, condition = fit_sbi(theta_train, x_train, task, args.seed)
            else:
                seconds, epochs, condition = fit_ours(method, theta_train, x_train, task, args.seed)
            kls = torch.tensor([kl_from_reference(task.reference(x_o), condition(x_o), seed=i)
                                for i, x_o in enumerate(x_obs)])
            rows.append((task.name, method, seconds, epochs, kls.mean().item(), kls.std().item() / math.sqrt(len(kls))))
            print(f"{task.name:16s} {method:12s} fit {seconds:7.1f} s  epochs {epochs:4d}  KL {rows[-1][4]:.3f} ± {rows[-1][5]:.3f}",
                  flush=True)
    print(f"\n{args.sims} simulations, {args.obs} observations, {REF_DRAWS} reference draws each, 1 thread\n")
    print("| simulator | method | fit time (s) | epochs | KL(ref ‖ q), mean ± s.e. |")
    print("|---|---|---:|---:|---:|")
    for name, method, seconds, epochs, kl, se in rows:
        print(f"| {name} | {method} | {seconds:.1f} | {epochs} | {kl:.3f} ± {se:.3f} |")


if __name__ == "__main__":
    main()

"""The condition stage's product temperature (inference/bayessim/set_calibration.py) at ShadowHand's size, read
set by set (a baseline commit's code) and as one MixtureStack (this checkout's), interleaved in one process.

    python benchmarks/condition_speed.py [--baseline 8e8ce22] [--dims 32] [--sets 100] [--trajectories 2 3]
        [--reps 2] [--epochs 5] [--profile]

ShadowHand's default model (mdnn_projected_gaussian_ensemble: 3 networks, one full-covariance Gaussian each, inputs
projected), fitted in probit space to synthetic pairs x = A theta + noise over a box prior of `--dims` parameters
for `--epochs` epochs, gives the per-trajectory posteriors; each of `--sets` held-out parameter vectors gets a set
of n = `--trajectories` simulations of the same map, and both codes fit the temperature on them as the pipeline's
condition stage does (100 sets, 500 draws per HPD level, products kept to 50 components). The baseline is the
package at `--baseline`, extracted with `git archive` and imported under another name. Rows: seconds of the whole
fit (sets' products built and the temperature searched), the fitted temperature of each, and the largest
difference between their records' shares inside (0 where the random streams agree). `--profile` adds cProfile's
top functions of one fit of each.
"""

from __future__ import annotations

import argparse
import cProfile
import importlib
import importlib.util
import io
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from bayessim_exp import api
from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.inference.bayessim.condition import tempered_products
from bayessim_exp.inference.bayessim.set_calibration import set_importance_draws, simulated_sets_temperature

DRAWS = 500  # diagnostics.coverage_samples
LEVELS = (0.5, 0.9)  # diagnostics.levels
MAX_COMPONENTS = 50  # method.max_components
IMPORTANCE_DRAWS = set_importance_draws(100_000, DRAWS)
SEED = 0
OLD = "bayessim_exp_baseline"


def baseline(commit: str, root: Path):
    """The package at `commit`, imported as OLD (its imports are relative)."""
    repo = Path(__file__).resolve().parents[1]
    archive = subprocess.run(["git", "-C", str(repo), "archive", commit, "src/bayessim_exp"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(root)], input=archive, check=True)
    (root / "src" / "bayessim_exp").rename(root / OLD)
    # imported from its directory by name: its submodules are found through the package's own __path__
    spec = importlib.util.spec_from_file_location(OLD, root / OLD / "__init__.py")
    sys.modules[OLD] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sys.modules[OLD])
    return (importlib.import_module(f"{OLD}.inference.bayessim.set_calibration"),
            importlib.import_module(f"{OLD}.inference.bayessim.condition"),
            importlib.import_module(f"{OLD}.distributions.mixture"),
            importlib.import_module(f"{OLD}.distributions.independent"),
            importlib.import_module(f"{OLD}.distributions.probit"))


def problem(dim: int, epochs: int):
    """(prior, fitted model, held-out parameters [sets, D], simulate) for synthetic pairs x = A theta + noise."""
    g = torch.Generator().manual_seed(0)
    prior = BoxUniform(torch.zeros(dim), torch.ones(dim))
    a = torch.randn(dim, 3 * dim, generator=g)
    theta = torch.rand(3000, dim, generator=g)
    x = theta @ a + 0.1 * torch.randn(3000, 3 * dim, generator=g)
    fitted = api.fit_posterior_model("mdnn", theta, x, prior=prior, probit=True, covariance="full", components=1,
                                     project_inputs=True, ensemble=3, max_epochs=epochs)

    def simulate(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        noise = 0.1 * torch.randn(len(t), 3 * dim, generator=torch.Generator().manual_seed(1))
        return torch.ones(len(t), dtype=torch.bool), (t.float() @ a + noise)

    held_out = prior.sample((1000,), generator=torch.Generator().manual_seed(2))
    return prior, fitted, held_out, simulate


def fit_new(prior, fitted, theta, n, simulate):
    def products_of(x):
        sets = [[fitted.model.conditional(x_i) for x_i in x_set] for x_set in x]
        return tempered_products(sets, prior, MAX_COMPONENTS, None, SEED, fitted.probit, IMPORTANCE_DRAWS)

    return simulated_sets_temperature(theta, n, simulate, products_of, LEVELS, DRAWS, SEED)


def fit_old(old, prior, fitted, theta, n, simulate):
    set_calibration, condition, mixture, independent, probit = old
    old_prior = independent.BoxUniform(prior.low, prior.high)
    old_probit = probit.ProbitTransform(old_prior)

    def product_of(x_set):
        qs = [fitted.model.conditional(x_i) for x_i in x_set]
        qs = [mixture.GaussianMixture(q.log_weights, q.means, q.covs) for q in qs]
        return condition.tempered_product(qs, old_prior, MAX_COMPONENTS, None, SEED, old_probit, IMPORTANCE_DRAWS,
                                          warn=False)

    return set_calibration.simulated_sets_temperature(theta, n, simulate, product_of, LEVELS, DRAWS, SEED)


def largest_difference(a: dict, b: dict) -> float:
    if a.keys() != b.keys():
        return float("inf")
    return max(abs(a[t][lv] - b[t][lv]) for t in a for lv in a[t])


def profiled(fit) -> str:
    profile = cProfile.Profile()
    profile.runcall(fit)
    out = io.StringIO()
    pstats.Stats(profile, stream=out).sort_stats("tottime").print_stats(12)
    return out.getvalue()


def compare(old, case: tuple, n: int, reps: int, profile: bool) -> str:
    """One table row: the fastest of `reps` interleaved fits of each code (so a machine's drift spreads over
    both), their temperatures and the largest difference between their records' shares inside."""
    prior, fitted, theta, simulate = case
    fits = {"old": lambda: fit_old(old, prior, fitted, theta, n, simulate),
            "new": lambda: fit_new(prior, fitted, theta, n, simulate)}
    times, results = {"old": [], "new": []}, {}
    for _ in range(reps):
        for name, fit in fits.items():
            start = time.perf_counter()
            results[name] = fit()
            times[name].append(time.perf_counter() - start)
    t_old, t_new = min(times["old"]), min(times["new"])
    diff = largest_difference(results["old"][1]["inside"], results["new"][1]["inside"])
    row = (f"| {theta.shape[1]} | {n} | {t_old:.2f} | {t_new:.2f} | {t_old / t_new:.1f}x | "
           f"{results['old'][0]:.4g} / {results['new'][0]:.4g} | {diff:.3g} |")
    return row + ("\n" + profiled(fits["old"]) + profiled(fits["new"]) if profile else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default="8e8ce22")
    parser.add_argument("--dims", type=int, nargs="+", default=[32])
    parser.add_argument("--sets", type=int, default=100)
    parser.add_argument("--trajectories", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--reps", type=int, default=2)
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; baseline {args.baseline}, new: checkout at "
          f"{commit} (uncommitted changes included); {args.sets} sets, {DRAWS} draws per HPD level")
    with tempfile.TemporaryDirectory() as root:
        old = baseline(args.baseline, Path(root))
        print("| parameters | n | baseline s | new s | speed-up | temperature baseline / new | largest share difference |")
        print("|---:|---:|---:|---:|---:|---|---:|")
        for dim in args.dims:
            prior, fitted, held_out, simulate = problem(dim, args.epochs)
            case = (prior, fitted, held_out[:args.sets].double(), simulate)
            for n in args.trajectories:
                print(compare(old, case, n, args.reps, args.profile), flush=True)


if __name__ == "__main__":
    main()

"""The cost of fitting the product's temperature (inference/bayessim/set_calibration.py) in many dimensions.

    python benchmarks/product_temperature.py [--dims 13 32 102] [--sets 4] [--trajectories 3] [--temperatures 8]

The search places each simulated set's parameters in the set's tempered product at up to 15 temperatures, for
100 sets by default. Per-trajectory posteriors here come from ShadowHand_more's default model (an ensemble of 3
mixture density networks with 5 diagonal components each, inputs projected) fitted for 3 epochs to synthetic
pairs x = A theta + noise: the cost depends on the mixtures' sizes and the dimension, not on what they learnt.
Rows per dimension, seconds per set for `--temperatures` temperatures, with the HPD level of the set's
parameters among 500 draws at each (what the search computes):

- `rebuilt per temperature` (the baseline): correction.posterior at each temperature, the product of the
  set's mixtures recomputed every time;
- `product once`: condition.tempered_product, what the search runs: the product computed at the first
  temperature and tempered after.

and the product of one set's mixtures kept to its 50 heaviest components after each factor (correction.py):
the baseline computes every one of the K1 x K2 components' means and covariances and then prunes, the new
row (GaussianMixture.product with max_components) those of the kept components only.
"""

from __future__ import annotations

import argparse
import time

import torch

from bayessim_exp import api
from bayessim_exp.distributions.hpd import own_level
from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.distributions.probit import ProbitPosterior, standard_normal_prior
from bayessim_exp.inference.bayessim.condition import tempered_product
from bayessim_exp.inference.bayessim.correction import posterior
from bayessim_exp.inference.bayessim.set_calibration import COARSE

MAX_COMPONENTS = 50
DRAWS = 500


def conditionals(dim: int, sets: int, trajectories: int):
    """(prior, probit transform, parameters [sets, D], per-trajectory posteriors [sets][trajectories])."""
    g = torch.Generator().manual_seed(0)
    prior = BoxUniform(torch.zeros(dim), torch.ones(dim))
    theta = torch.rand(3000, dim, generator=g)
    x = theta @ torch.randn(dim, 3 * dim, generator=g) + 0.1 * torch.randn(3000, 3 * dim, generator=g)
    fitted = api.fit_posterior_model("mdnn", theta, x, prior=prior, probit=True, covariance="diagonal",
                                     project_inputs=True, ensemble=3, max_epochs=3)
    qs = [[fitted.model.conditional(x[s * trajectories + i]) for i in range(trajectories)] for s in range(sets)]
    return prior, fitted.probit, theta[::trajectories][:sets].double(), qs


def rebuilt(qs: list, probit):
    """The posterior at a temperature built anew at each call (fitted in probit space: N(0, I) prior)."""
    prior = standard_normal_prior(probit.dim)
    return lambda tau: ProbitPosterior(posterior(qs, prior, max_components=MAX_COMPONENTS, temperature=tau), probit)


def levels(products, theta: torch.Tensor, temperatures) -> list[float]:
    generator = torch.Generator().manual_seed(0)
    return [own_level(product(tau), t, DRAWS, generator) for tau in temperatures for product, t in zip(products, theta)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dims", type=int, nargs="+", default=[13, 32, 102])
    parser.add_argument("--sets", type=int, default=4)
    parser.add_argument("--trajectories", type=int, default=3)
    parser.add_argument("--temperatures", type=int, default=8, help="the first of set_calibration.COARSE")
    args = parser.parse_args()
    temperatures = COARSE[:args.temperatures]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; {args.sets} sets of {args.trajectories} "
          f"trajectories, {len(temperatures)} temperatures, {DRAWS} draws per HPD level")
    print("| parameters | what | baseline s | new s | speed-up | same levels |")
    print("|---:|---|---:|---:|---:|---|")
    for dim in args.dims:
        prior, probit, theta, qs = conditionals(dim, args.sets, args.trajectories)
        start = time.perf_counter()
        baseline = levels([rebuilt(q, probit) for q in qs], theta, temperatures)
        mid = time.perf_counter()
        new = levels([tempered_product(q, prior, MAX_COMPONENTS, None, 0, probit) for q in qs], theta, temperatures)
        end = time.perf_counter()
        per_set = ((mid - start) / args.sets, (end - mid) / args.sets)
        print(f"| {dim} | temperature search, per set | {per_set[0]:.2f} | {per_set[1]:.2f} | "
              f"{per_set[0] / per_set[1]:.1f}x | {'yes' if baseline == new else 'NO'} |")

        start = time.perf_counter()
        full = product_of(qs[0], lambda out, q: out.product(q).prune(MAX_COMPONENTS))
        mid = time.perf_counter()
        kept = product_of(qs[0], lambda out, q: out.product(q, MAX_COMPONENTS))
        end = time.perf_counter()
        same = torch.allclose(full.covs, kept.covs, atol=1e-10) and torch.allclose(full.means, kept.means, atol=1e-10)
        sizes = " x ".join(str(q.num_components) for q in qs[0])
        print(f"| {dim} | product of {sizes} components, kept to {MAX_COMPONENTS} after each | {mid - start:.3f} | "
              f"{end - mid:.3f} | {(mid - start) / (end - mid):.1f}x | {'yes' if same else 'NO'} |")


def product_of(mixtures, multiply):
    out = mixtures[0].prune(MAX_COMPONENTS)
    for q in mixtures[1:]:
        out = multiply(out, q)
    return out


if __name__ == "__main__":
    main()

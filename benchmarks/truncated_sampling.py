"""The truncated proposal in many parameters: the share of candidates kept (the rejection sampler's acceptance), the
region's prior mass and the seconds to build the proposal and draw a round's parameters, for posteriors in probit
space of the shapes the many-parameter tasks give (docs/benchmarks.md, "Rounds that escape and focus").

    python benchmarks/truncated_sampling.py [--draws 10000]

Each posterior sits in the prior's joint tail (every probit coordinate at -1.3, a multiplier of 1 in [0.1, 10]) with
standard deviations given per row, its axes rotated at random: `narrow`, all 0.05; `mixed`, a third at 0.05 and the
rest at 0.9 (identified and barely identified parameters); `3 components`, three narrow ones a little apart (an
ensemble's mixture); `50 diagonal components`, `mixed`'s spreads on the parameters' own axes in 50 components a
little apart (a diagonal ensemble's product over three trajectories, as ShadowHand_more's third round has). Before
distributions/relaxed_cover.py the candidates were the prior restricted to a box around the region: in 30
dimensions it kept 0.00095 of them on ShadowHand's round 2 and the round simulated from the prior.
Against another commit's code: PYTHONPATH=<its src> python benchmarks/truncated_sampling.py.
"""

from __future__ import annotations

import argparse
import time

import torch

from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.distributions.probit import ProbitPosterior, ProbitTransform
from bayessim_exp.distributions.truncated_prior import TruncatedPrior

SHAPES = ("narrow", "mixed", "3 components", "50 diagonal components")


def posterior(dim: int, shape: str, generator: torch.Generator) -> GaussianMixture:
    components = {"3 components": 3, "50 diagonal components": 50}.get(shape, 1)
    std = torch.full((dim,), 0.05, dtype=torch.float64)
    if shape in ("mixed", "50 diagonal components"):
        std[dim // 3:] = 0.9
    means = -1.3 + 0.1 * torch.randn(components, dim, dtype=torch.float64, generator=generator)
    if shape == "50 diagonal components":  # a diagonal model's product over three trajectories, capped at 50
        return GaussianMixture(torch.zeros(components), means, torch.diag(std**2).expand(components, dim, dim))
    rotation, _ = torch.linalg.qr(torch.randn(dim, dim, dtype=torch.float64, generator=generator))
    cov = rotation @ torch.diag(std**2) @ rotation.T
    return GaussianMixture(torch.zeros(components), means, cov.expand(components, dim, dim))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=10_000, help="parameters drawn, as a round's collect stage does")
    args = parser.parse_args()
    print("| parameters | posterior | candidates kept | log prior mass of the region | seconds: build / draw |")
    print("|---|---|---|---|---|")
    for dim in (30, 102):
        prior = BoxUniform(torch.full((dim,), 0.1, dtype=torch.float64), torch.full((dim,), 10.0, dtype=torch.float64))
        for shape in SHAPES:
            inner = posterior(dim, shape, torch.Generator().manual_seed(dim))
            start = time.perf_counter()
            proposal = TruncatedPrior(prior, ProbitPosterior(inner, ProbitTransform(prior)), seed=1)
            built = time.perf_counter()
            proposal.sample((args.draws,), generator=torch.Generator().manual_seed(2))
            drawn = time.perf_counter()
            print(f"| {dim} | {shape} | {proposal.acceptance:.3f} | {proposal.log_mass:.1f} | "
                  f"{built - start:.1f} / {drawn - built:.1f} |")


if __name__ == "__main__":
    main()

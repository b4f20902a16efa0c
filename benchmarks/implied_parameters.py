"""Where one foreign pendulum trajectory's summaries put the parameters, all features and time blocks apart.

    PYTHONPATH=src python benchmarks/implied_parameters.py                     # rk4, euler, scipy and ours, 4 settings
    PYTHONPATH=src python benchmarks/implied_parameters.py --sources rk4 ours --overrides summarizer=waypoints

For each source and hidden setting of benchmarks/foreign_dynamics.py, one trajectory (n = 1, the same data seed)
is replayed in our simulator at `--replays` parameter draws around the truth (standard deviation `--spread` of the
prior's range per parameter) and summarized by the default summarizer (or the one `--overrides` chooses). The
replayed check's linear map (diagnostics/replayed_check.implied_parameters) gives the parameters the real summary
implies:
- from every feature: what the replay widening and a posterior centred by the summaries see; its offset from the
  truth is the part of the model error that looks like a parameter shift, which no residual can show;
- from each of `--blocks` consecutive blocks of features alone (the start summarizer's features run step by step,
  so a block is a stretch of time): their root-mean-square distance from the all-feature value, beside the replays'
  own (the map's curvature). On data our simulator reproduces the two agree; a model error that is not a parameter
  shift moves the blocks apart;
- the jackknife p-value: the rank of the real summary's leave-one-block-out variance among the replays'.
The best fit of our model to the recorded states of the first 20 steps (independent_pendulum.best_fit, as in the
foreign-dynamics benchmark) is printed beside them.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import torch


def block_readings(z: torch.Tensor, theta: torch.Tensor, z_real: torch.Tensor, blocks: int) -> dict:
    """z [m, F] replays' standardised summaries at theta [m, D]; z_real [1, F]. The implied parameters of the real
    summary from all features, the RMS distance of the block-alone readings from it (real and the replays' median)
    and the jackknife p-value of the real summary's leave-one-block-out variance among the replays'."""
    from bayessim_exp.diagnostics.replayed_check import implied_parameters, rank_p_value

    queries = torch.cat([z, z_real])
    every = implied_parameters(z, theta, queries)[0]
    block = torch.arange(z.shape[1]) * blocks // z.shape[1]
    alone = torch.stack([implied_parameters(z[:, block == k], theta, queries[:, block == k])[0] for k in range(blocks)])
    left_out = torch.stack([implied_parameters(z[:, block != k], theta, queries[:, block != k])[0]
                            for k in range(blocks)])
    spread = (alone - every).pow(2).mean(0).sqrt()  # [m + 1, D]
    jackknife = (left_out - left_out.mean(0)).pow(2).sum((0, 2))  # [m + 1]
    return {"implied": every[-1], "block_spread": spread[-1], "replay_block_spread": spread[:-1].median(0).values,
            "jackknife_p": rank_p_value(jackknife[:-1], jackknife[-1])}


@dataclasses.dataclass
class Setup:
    """What every case reads, built once: the task, its prior, the simulator and the summarizer."""

    task: object
    prior: object
    sims: object
    summarize: object

    @classmethod
    def compose(cls, overrides: list[str]) -> Setup:
        from bayessim_exp import api, registry
        from bayessim_exp.sim.pool import SimulatorPool

        cfg = api.compose(["sim=native", *overrides])
        task = registry.build("task", cfg.task)
        return cls(task, registry.build("prior", cfg.prior, spec=task.spec),
                   SimulatorPool(registry.build("sim", cfg.sim), task, 4096), registry.build("summarizer", cfg.summarizer))


def reading(setup: Setup, source: str, mass: float, length: float, seed: int, args, work: Path) -> dict:
    import foreign_dynamics  # benchmarks/foreign_dynamics.py, beside this script
    from bayessim_exp.diagnostics.replay import replay
    from bayessim_exp.diagnostics.replayed_check import standardised
    from bayessim_exp.models.base import constant_columns
    from bayessim_exp.real import load_trajectories
    from bayessim_exp.testing import independent_pendulum

    path = work / f"{source}_{mass}_{length}.npz"
    foreign_dynamics.write_case(source, mass, length, 1, seed, "random", path)
    with np.load(path) as data:
        real = load_trajectories(dict(data), setup.task, foreign_dynamics.HORIZON, str(path))
    g = torch.Generator().manual_seed(0)
    truth = torch.tensor([mass, length], dtype=torch.float64)
    ranges = (setup.prior.high - setup.prior.low).double()
    theta = truth + args.spread * ranges * torch.randn(args.replays, 2, generator=g, dtype=torch.float64)
    first = torch.zeros(args.replays, dtype=torch.long)
    x = setup.summarize(replay(setup.sims, theta, real, first)).double()
    prior_draws = setup.prior.sample((args.replays,), generator=g).double()
    x_prior = setup.summarize(replay(setup.sims, prior_draws, real, first)).double()
    scale, keep = x_prior.std(0), ~constant_columns(x_prior)
    found = block_readings(standardised(x, scale, keep), theta,
                           standardised(setup.summarize(real).double(), scale, keep), args.blocks)
    fit = independent_pendulum.best_fit(setup.sims, real, foreign_dynamics.FIT_STEPS)
    return {"source": source, "truth": [mass, length], "best_fit": fit.tolist(),
            **{k: v.tolist() if torch.is_tensor(v) else v for k, v in found.items()}}


def table(rows: list[dict]) -> list[str]:
    def pair(values, fmt="{:.3f}") -> str:
        return ", ".join(fmt.format(v) for v in values)

    lines = ["| source | mass, length | implied by every feature | its offset from the truth | best fit (states) | "
             "block readings' RMS distance, real / replays | jackknife p |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        offset = pair([100 * (i / t - 1) for i, t in zip(r["implied"], r["truth"])], "{:+.1f} %")
        lines.append(f"| {r['source']} | {pair(r['truth'], '{}')} | {pair(r['implied'])} | {offset} | "
                     f"{pair(r['best_fit'])} | {pair(r['block_spread'], '{:.4f}')} / "
                     f"{pair(r['replay_block_spread'], '{:.4f}')} | {r['jackknife_p']:.3f} |")
    return lines


def main() -> None:
    import foreign_dynamics

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sources", nargs="+", default=["ours", "rk4", "euler", "scipy"],
                    choices=list(foreign_dynamics.SOURCES))
    ap.add_argument("--settings", type=int, default=len(foreign_dynamics.SETTINGS),
                    help="how many of the hidden parameter settings")
    ap.add_argument("--replays", type=int, default=200)
    ap.add_argument("--spread", type=float, default=0.002, help="replay draws' std, as a share of the prior's range")
    ap.add_argument("--blocks", type=int, default=5, help="consecutive feature blocks (stretches of time)")
    ap.add_argument("--overrides", nargs="*", default=[], help="config overrides, e.g. summarizer=waypoints")
    args = ap.parse_args()
    torch.set_num_threads(1)
    setup, rows = Setup.compose(args.overrides), []
    with tempfile.TemporaryDirectory() as work:
        for source in args.sources:
            for k, (mass, length) in enumerate(foreign_dynamics.SETTINGS[: args.settings]):
                rows.append(reading(setup, source, mass, length, 100 + k, args, Path(work)))  # foreign_dynamics' data seeds
                print(table(rows[-1:])[-1], flush=True)
    print("\n".join(["", *table(rows)]))


if __name__ == "__main__":
    main()

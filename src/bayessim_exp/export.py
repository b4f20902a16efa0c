"""What a run handed on to domain randomization, in files that tools outside the project read.

    python -m bayessim_exp.export <run_dir> [--round R] [--samples N] [--seed S] [--out DIR]
                                            [--mjcf mean|median|draw:K ...] [--dr-interval 0.99]

writes into DIR (by default <run_dir>/export/round_RRR):

    samples.csv       N draws, a column per parameter, the names as header: plain CSV for any reader
    samples.npz       the same draws (`samples` [N, D], `names`) and where they come from (`round`, `handed_on_round`,
                      0 for the prior, `prior`, `seed`, `task`, `run_dir`)
    quantiles.csv     per parameter: mean, std, 5/50/95 % quantiles and the prior's range
    dr.yaml           a domain-randomization config in the task's own vocabulary (below)
    <Task>_mean.xml   the task's MJCF with the distribution's mean written in (--mjcf: also median, draw:K, the
                      K-th row of samples.csv counted from 0)

The distribution is what round R (the last by default) handed on: its own posterior, an earlier round's or the
prior where its guard fell back (results.json's rounds[R-1].guard); dr.yaml, the MJCF files and samples.npz say
which. dr.yaml holds `parameters` as a task YAML declares them (conf/task/<Task>.yaml: operation, nominal, targets),
each `range` the distribution's central --dr-interval (the prior's range where the prior was handed on), and the
Hydra `overrides` that set those ranges on a run of the task; `marginals` (mean, std, 5/50/95 % quantiles, the
support) for a stack that draws each parameter alone, a Gaussian or a clipped one; `correlation` of the draws;
and `samples`, the file of joint draws, which a stack that resamples them uses exactly.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np
import yaml
from omegaconf import OmegaConf

from .api import HandedOn, ParameterSamples, Run, load_run
from .diagnostics.scoring import quantile_key
from .distributions.base import QUANTILE_LEVELS, ParameterDistribution
from .errors import ConfigError
from .tasks.parameterized import write_mjcf


def export_run(run: Run, out_dir: str | Path, round_index: int | None = None, n: int = 1000, seed: int = 0,
               mjcf: tuple[str, ...] = ("mean",), dr_interval: float = 0.99) -> dict[str, Path]:
    """Write the files above for `run`; returns {what: path}. Arguments are checked before anything is drawn."""
    handed = run.handed_on(round_index)
    draws_wanted = _check(n, mjcf, dr_interval)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dist = run.posterior(handed.round)
    samples = run.samples(n, handed.round, seed)
    names, task = samples.names, run.task
    files = {"samples.csv": _write_csv(out / "samples.csv", names, samples.values.numpy()),
             "samples.npz": _write_npz(out / "samples.npz", run, samples)}
    marginals = _marginals(dist, task)
    files["quantiles.csv"] = _write_csv(out / "quantiles.csv", ["parameter", *MARGINAL_COLUMNS],
                                        [[name, *row] for name, row in zip(names, marginals.tolist())])
    files["dr.yaml"] = out / "dr.yaml"
    files["dr.yaml"].write_text(dr_yaml(run, handed, dist, samples, dr_interval, marginals))
    points = {"mean": marginals[:, MARGINAL_COLUMNS.index("mean")],
              "median": marginals[:, MARGINAL_COLUMNS.index(quantile_key(0.5))]}
    points.update({f"draw{k}": samples.values[k].numpy() for k in draws_wanted})
    for what in mjcf:
        key = what.replace(":", "")
        values = points[key]
        said = ", ".join(f"{name}={v:.6g}" for name, v in zip(names, values))
        comment = (f" {task.name} with the {key} of what round {handed.round} of {run.path} handed on "
                   f"({handed.description}{'' if handed.is_prior else ', not the prior'}) written in: {said} ")
        files[what] = write_mjcf(task, values, out / f"{task.name}_{key}.xml", comment)
    return files


def _check(n: int, mjcf: tuple[str, ...], dr_interval: float) -> list[int]:
    """The draws --mjcf asks for; a clear error for any argument that cannot work."""
    if n < 2:
        raise ValueError(f"--samples must be at least 2, got {n}")
    if not 0 < dr_interval <= 1:
        raise ValueError(f"--dr-interval must lie in (0, 1], got {dr_interval}")
    draws = []
    for what in mjcf:
        if what in ("mean", "median"):
            continue
        k = what.removeprefix("draw:")
        if not what.startswith("draw:") or not k.isdigit():
            raise ValueError(f"--mjcf {what}: write mean, median or draw:K (K a row of samples.csv, from 0)")
        if int(k) >= n:
            raise ValueError(f"--mjcf {what}: there are {n} draws (rows 0 to {n - 1})")
        draws.append(int(k))
    return draws


MARGINAL_COLUMNS = ["mean", "std", *map(quantile_key, QUANTILE_LEVELS), "low", "high"]


def _marginals(dist: ParameterDistribution, task) -> np.ndarray:
    """Per parameter (rows) the MARGINAL_COLUMNS: moments, quantiles and the support, computed once for every file."""
    low, high = _support(dist, task)
    return np.column_stack([dist.mean.double().numpy(), dist.stddev.double().numpy(),
                            dist.quantiles(QUANTILE_LEVELS).T.numpy(), low, high])


def _support(dist: ParameterDistribution, task) -> tuple[np.ndarray, np.ndarray]:
    """The box the distribution lives on: its own, else the task's ranges."""
    if dist.low is not None and dist.high is not None:
        return dist.low.double().numpy(), dist.high.double().numpy()
    return task.spec.low, task.spec.high


def _write_csv(path: Path, header: list[str], rows) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows([[v if isinstance(v, str) else repr(float(v)) for v in row] for row in rows])
    return path


def _write_npz(path: Path, run: Run, s: ParameterSamples) -> Path:
    np.savez(path, samples=s.values.numpy(), names=np.array(s.names), round=s.handed_on.round,
             handed_on_round=s.handed_on.source, prior=s.handed_on.is_prior, seed=s.seed,
             task=run.results["task"], run_dir=str(run.path))
    return path


def _g(value: float) -> float | None:
    """6 significant digits (the precision of an MJCF too); None where a number does not exist."""
    value = float(value)
    return float(f"{value:.6g}") if math.isfinite(value) else None


def dr_yaml(run: Run, handed: HandedOn, dist: ParameterDistribution, samples: ParameterSamples,
            interval: float, marginals: np.ndarray) -> str:
    """dr.yaml's text (the module docstring says what it holds); `marginals` as _marginals gives them."""
    task, names = run.task, samples.names
    declared = OmegaConf.to_container(run.config.task.parameters, resolve=True)
    if handed.is_prior:
        lows, highs = task.spec.low, task.spec.high
        ranges_are = "the prior's range: the prior was handed on"
    else:
        tail = (1 - interval) / 2
        q = dist.quantiles((tail, 1 - tail)).numpy()
        lows, highs = np.maximum(q[0], task.spec.low), np.minimum(q[1], task.spec.high)
        ranges_are = f"the central {100 * interval:g} % interval of the distribution's marginal"
    parameters, overrides = {}, []
    for j, name in enumerate(names):
        entry = dict(declared[name])
        entry["range"] = [_g(lows[j]), _g(highs[j])]
        parameters[name] = {k: entry[k] for k in ("range", "operation", "nominal", "targets") if k in entry}
        overrides.append(f"task.parameters.{name}.range=[{_g(lows[j])},{_g(highs[j])}]")
    by_name = {name: {column: _g(v) for column, v in zip(MARGINAL_COLUMNS, row)}
               for name, row in zip(names, marginals.tolist())}
    corr = np.atleast_2d(np.corrcoef(samples.values.numpy(), rowvar=False))
    doc = {
        "task": task.name,
        "source": {"run_dir": str(run.path), "method": run.results.get("method"), "round": handed.round,
                   "handed_on": handed.description, "handed_on_round": handed.source, "prior": handed.is_prior},
        "parameters": parameters,
        "overrides": overrides,
        "marginals": by_name,
        "correlation": [[_g(v) for v in row] for row in corr.tolist()],
        "samples": {"file": "samples.csv", "draws": len(samples), "seed": samples.seed},
    }
    head = [
        f"Domain randomization for {task.name}: what round {handed.round} of {run.path} handed on,",
        f"{handed.description}{'' if handed.is_prior else ' (not the prior)'}. Written by python -m bayessim_exp.export.",
        f"parameters: as conf/task/{task.name}.yaml declares them; each range is {ranges_are}.",
        f"  A run on them: python -m bayessim_exp task={task.name} followed by the overrides below.",
        "marginals: each parameter's mean, std, 5/50/95 % quantiles and support (low, high), for a stack that",
        "  draws parameters one by one (a Gaussian with this mean and std, kept within the support);",
        "correlation: of the draws in samples.csv (rows and columns in the order of parameters);",
        "samples: joint draws, a column per parameter, for a stack that resamples them (exact).",
    ]
    return "".join(f"# {line}\n" for line in head) + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None,
                                                                      width=120)


def _print_summary(run: Run, handed: HandedOn, files: dict[str, Path]) -> None:
    print(f"{run.results['task']}, round {handed.round} of {run.path}: handed on {handed.description}")
    columns = MARGINAL_COLUMNS[:-2]  # the support is in quantiles.csv
    print(f"{'parameter':<24}" + "".join(f"{c:>12}" for c in columns))
    with files["quantiles.csv"].open() as f:
        for row in csv.DictReader(f):
            print(f"{row['parameter']:<24}" + "".join(f"{float(row[c]):>12.5g}" for c in columns))
    folder = files["samples.csv"].parent
    print(f"wrote to {folder}: " + ", ".join(p.name for p in files.values()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bayessim_exp.export", description=__doc__.split("\n\n")[0],
                                     epilog="The module's docstring (bayessim_exp/export.py) describes each file.")
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--round", type=int, default=None, help="finished round (1, 2, ...); default: the last")
    parser.add_argument("--samples", type=int, default=1000, help="draws in samples.csv / .npz (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default <run_dir>/export/round_RRR)")
    parser.add_argument("--mjcf", action="append", default=None, metavar="WHAT",
                        help="an MJCF with mean, median or draw:K written in; repeatable (default: mean)")
    parser.add_argument("--dr-interval", type=float, default=0.99,
                        help="dr.yaml's ranges: this central interval of each marginal (default 0.99)")
    args = parser.parse_args(argv)
    mjcf = tuple(args.mjcf or ("mean",))
    try:  # every argument and the run dir checked before anything is drawn or built
        run = load_run(args.run_dir)
        handed = run.handed_on(args.round)
        if args.round is None and len(run.results["rounds"]) < run.rounds_planned:
            raise ValueError(f"{args.run_dir} finished {len(run.results['rounds'])} of its {run.rounds_planned} "
                             "rounds (still running, stopped or killed): resume it, or name a finished round with "
                             "--round")
        _check(args.samples, mjcf, args.dr_interval)
    except (FileNotFoundError, ValueError, ConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = args.out or args.run_dir / "export" / f"round_{handed.round:03d}"
    files = export_run(run, out, handed.round, args.samples, args.seed, mjcf, args.dr_interval)
    _print_summary(run, handed, files)
    return 0


if __name__ == "__main__":
    sys.exit(main())

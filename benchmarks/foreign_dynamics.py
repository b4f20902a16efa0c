"""Foreign-dynamics benchmark: the whole pipeline on pendulum logs from simulators nobody here wrote.

    PYTHONPATH=src python benchmarks/foreign_dynamics.py --jobs 14 --device cuda --out /tmp/foreign   # 16 cores, a GPU
    PYTHONPATH=src python benchmarks/foreign_dynamics.py --quick --jobs 2 --out /tmp/foreign_quick
    PYTHONPATH=src python benchmarks/foreign_dynamics.py --from-json docs/figures/foreign_dynamics.json --section

Each case writes n real trajectories (n = 1 and 5) at hidden parameters inside the prior box into an
npz and runs `python -m bayessim_exp real=file real.path=<npz>` at its defaults (3 rounds of 10,000
simulations, collect policy `replay`; --quick: 2 rounds of 2,000). Sources (bayessim_exp/testing/
independent_pendulum.py):

- well specified: `ours`, our own simulator (MuJoCo, the task's MJCF);
- the same physics, other integrators and time steps (the best fit of our model class is near the truth,
  not at it): `rk4` (50 substeps per control step), `euler` (semi-implicit at 2 ms), `scipy` (adaptive DOP853);
- physics our model lacks: `damped` (0.1 N m s/rad), `friction` (Coulomb, 0.3 N m), `lag` (a first-order
  motor with a 0.1 s time constant), `offset` (the angle logged 0.3 rad off).

Per case: the HPD level of the truth and of the best fit of our model (least squares of our replays to the
recorded states of the first 20 steps, over the prior box: independent_pendulum.best_fit) under the final posterior (inside the
90 % region iff < 0.9), the log-density gain at them, the final temperature of the replay widening, and
whether the final round flagged a model mismatch. The summary gives, per group and n, the share of cases
with the truth or the best fit inside the 90 % region and the share flagged. `--sine` adds the
sine-excitation cases (our simulator at 1.6 kg, 0.7 m, 5 trajectories driven by sines, as a robot log).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

SETTINGS = [(0.7, 0.35), (1.0, 0.5), (1.6, 0.7), (1.3, 0.85)]
SOURCES = {
    "ours": ("well specified", {}),
    "rk4": ("other integrator", {"integrator": "rk4"}),
    "euler": ("other integrator", {"integrator": "euler"}),
    "scipy": ("other integrator", {"integrator": "scipy"}),
    "damped": ("physics the model lacks", {"damping": 0.1}),
    "friction": ("physics the model lacks", {"friction": 0.3}),
    "lag": ("physics the model lacks", {"motor_lag": 0.1}),
    "offset": ("physics the model lacks", {"angle_offset": 0.3}),
}
HORIZON = 50  # conf/config.yaml collect.horizon
# the best fit matches the recorded states of the steps the default summary (`start`) reads: over all 50 a
# swinging pendulum's least squares has many local minima (replays at nearby parameters drift apart)
FIT_STEPS = 20


def write_case(source: str, mass: float, length: float, n: int, seed: int, actions: str, path: Path) -> None:
    """The npz real=file reads: our simulator for `ours`, the independent pendulum otherwise."""
    import torch

    from bayessim_exp import api, registry
    from bayessim_exp.policies import OpenLoopPolicy
    from bayessim_exp.real import save_trajectories
    from bayessim_exp.sim.pool import SimulatorPool
    from bayessim_exp.testing import independent_pendulum

    if source != "ours":
        np.savez(path, **independent_pendulum.simulate(mass, length, n, HORIZON, seed, actions=actions,
                                                       **SOURCES[source][1]))
        return
    cfg = api.compose(["sim=native"])
    task = registry.build("task", cfg.task)
    pool = SimulatorPool(registry.build("sim", cfg.sim), task, 4096)
    rng = np.random.default_rng(seed)
    state = task.reset_state(rng, n)
    acts = torch.as_tensor(independent_pendulum.excitation(actions, n, HORIZON, rng), dtype=torch.float32)
    traj = pool.rollout(np.tile([mass, length], (n, 1)), OpenLoopPolicy(acts), HORIZON, seed, state=state)
    save_trajectories(path, traj, np.array([mass, length]), ["mass", "length"])


def run_case(case: dict) -> dict:
    """One pipeline run on one case's data; the truth's and the best fit's place in the final posterior."""
    import torch

    torch.set_num_threads(1)
    from bayessim_exp import api, registry
    from bayessim_exp.real import load_trajectories
    from bayessim_exp.sim.pool import SimulatorPool
    from bayessim_exp.testing import independent_pendulum

    out = Path(case["dir"])
    # a clean directory: a run resumes from the stage files it finds, which an earlier run's would be
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    data_path = out / "real.npz"
    write_case(case["source"], case["mass"], case["length"], case["n"], case["seed"], case["actions"], data_path)
    t0 = time.perf_counter()
    results = api.run([f"real.path={data_path}", "real=file", "logging.progress=false", *case["overrides"]],
                      out_dir=out / "run")
    seconds = time.perf_counter() - t0
    posterior = api.load_run(out / "run").posterior()
    cfg = api.compose(["sim=native"])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    with np.load(data_path) as data:
        real = load_trajectories(dict(data), task, HORIZON, str(data_path))
    fit = independent_pendulum.best_fit(SimulatorPool(registry.build("sim", cfg.sim), task, chunk=4096), real,
                                        FIT_STEPS)
    truth = np.array([case["mass"], case["length"]])
    last = results["rounds"][-1]

    def gain(theta: np.ndarray) -> float:
        t = torch.as_tensor(theta, dtype=torch.float64)[None]
        return float(posterior.log_prob(t) - prior.log_prob(t))

    return {**{k: case[k] for k in ("group", "source", "mass", "length", "n", "actions")},
            "best_fit": fit.tolist(), "level_truth": independent_pendulum.hpd_level(posterior, truth),
            "level_best_fit": independent_pendulum.hpd_level(posterior, fit), "gain_truth": gain(truth),
            "gain_best_fit": gain(fit), "temperature": last["temperature"], "flagged": last["mismatch"]["flagged"],
            "reasons": last["mismatch"]["reasons"], "guard": last["guard"]["action"],
            "posterior_mean": list(last["posterior_mean"].values()), "posterior_std": list(last["posterior_std"].values()),
            "seconds": seconds}


def cases(args) -> list[dict]:
    # processes side by side simulating on one CPU thread each (a GPU machine's 16 cores); --device cuda fits there
    overrides = ["sim=native", f"device={args.device}", *(["rounds=2", "collect.trajectories=2000"] if args.quick else []),
                 *args.overrides]
    out = []
    for source in args.sources:
        for k, (mass, length) in enumerate(SETTINGS[: args.settings]):
            for n in args.trajectories:
                out.append({"group": SOURCES[source][0], "source": source, "mass": mass, "length": length, "n": n,
                            "seed": 100 + k, "actions": "random", "overrides": overrides,
                            "dir": str(args.out / f"{source}_{mass}_{length}_n{n}")})
    if args.sine:
        for seed in range(args.sine):
            out.append({"group": "sine excitation", "source": "ours", "mass": 1.6, "length": 0.7, "n": 5,
                        "seed": 200 + seed, "actions": "sine", "overrides": overrides,
                        "dir": str(args.out / f"sine_{seed}")})
    return out


def covered(r: dict) -> bool:
    """The truth or the best fit of our model lies inside the final posterior's 90 % region."""
    return min(r["level_truth"], r["level_best_fit"]) < 0.9


def summary(rows: list[dict]) -> list[str]:
    lines = ["| group | n | cases | median gain at the truth (share of the well-specified median) | truth or best fit "
             "in the 90 % region | best fit in it | flagged | widened (temperature < 1) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for group in dict.fromkeys(r["group"] for r in rows):
        for n in (1, 5):
            sel = [r for r in rows if r["group"] == group and r["n"] == n]
            if not sel:
                continue
            inside = sum(map(covered, sel))
            best_fit_inside = sum(r["level_best_fit"] < 0.9 for r in sel)
            flagged = sum(r["flagged"] for r in sel)
            widened = sum(r["temperature"] < 1 for r in sel)
            gain = float(np.median([r["gain_truth"] for r in sel]))
            well = [r["gain_truth"] for r in rows if r["group"] == "well specified" and r["n"] == n]
            share = f" ({gain / float(np.median(well)):.0%})" if well and float(np.median(well)) > 0 else ""
            lines.append(f"| {group} | {n} | {len(sel)} | {gain:+.1f}{share} | {inside} ({inside / len(sel):.0%}) | "
                         f"{best_fit_inside} ({best_fit_inside / len(sel):.0%}) | {flagged} ({flagged / len(sel):.0%}) "
                         f"| {widened} |")

    def share(sel: list[dict], hit) -> str:
        return f"{sum(map(hit, sel))} of {len(sel)}"

    lacking = [r for r in rows if r["group"] == "physics the model lacks"]
    ours = [r for r in rows if r["source"] == "ours"]
    lines += ["", f"Over all sources: covered {share([r for r in rows if r['n'] == 1], covered)} with one trajectory "
              f"and {share([r for r in rows if r['n'] == 5], covered)} with five; physics the model lacks flagged in "
              f"{share(lacking, lambda r: r['flagged'])}; our own simulator (sine excitation included) flagged in "
              f"{share(ours, lambda r: r['flagged'])}."]
    return lines


def table(rows: list[dict]) -> list[str]:
    lines = ["| source | mass | length | n | best fit | HPD level truth / best fit | gain truth / best fit | "
             "posterior mean +- std | temperature | flagged | s |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        mean = ", ".join(f"{m:.3f} +- {s:.3f}" for m, s in zip(r["posterior_mean"], r["posterior_std"]))
        lines.append(f"| {r['source']}{' (sine)' if r['actions'] == 'sine' else ''} | {r['mass']} | {r['length']} | "
                     f"{r['n']} | {r['best_fit'][0]:.3f}, {r['best_fit'][1]:.3f} | {r['level_truth']:.2f} / "
                     f"{r['level_best_fit']:.2f} | {r['gain_truth']:+.1f} / {r['gain_best_fit']:+.1f} | {mean} | "
                     f"{r['temperature']:.3g} | {'yes' if r['flagged'] else 'no'} | {r['seconds']:.0f} |")
    return lines


SECTION = """## Real data from simulators nobody here wrote: the foreign-dynamics benchmark

Each case is a whole default run, `python -m bayessim_exp real=file real.path=<npz>` (3 rounds of 10,000
simulations driven by `policy=replay`, the default with real data), on n = 1 or 5 pendulum trajectories of 50
steps recorded at hidden parameters inside the prior box by `src/bayessim_exp/testing/independent_pendulum.py`:
our own simulator (well specified); the same rod physics integrated otherwise (RK4 with 50 substeps,
semi-implicit Euler at 2 ms, SciPy's DOP853), where the best fit of our model class is near the truth but not
at it; and physics our model lacks (joint damping 0.1 N m s/rad, Coulomb friction 0.3 N m, a first-order
motor lag of 0.1 s, the angle logged 0.3 rad off). Random actions as the collect policy draws them, except the
sine-excitation cases (our simulator at 1.6 kg, 0.7 m, 5 trajectories driven by sines of 0.3-1.5 Hz, as a
robot's excitation log). Covered: the truth or the least-squares best fit of our model (its replays of the
first 20 steps closest to the recorded states) lies inside the final posterior's 90 % HPD region; flagged:
the final round's mismatch verdict.

{summary}

Per case: the HPD level of the truth and of the best fit (inside the 90 % region iff < 0.9), the log-density
gain over the prior there, the final posterior's mean and standard deviation, the temperature of the
widening (the product's fitted on simulated sets times the replay widening's; 1: none), the verdict, and the
run's seconds.

{table}
"""


def section(rows: list[dict]) -> str:
    return SECTION.format(summary="\n".join(summary(rows)), table="\n".join(table(rows))).strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/foreign_dynamics"))
    ap.add_argument("--jobs", type=int, default=2, help="runs at once (one thread each)")
    ap.add_argument("--sources", nargs="+", default=list(SOURCES), choices=list(SOURCES))
    ap.add_argument("--settings", type=int, default=len(SETTINGS), help="how many of the hidden parameter settings")
    ap.add_argument("--trajectories", type=int, nargs="+", default=[1, 5], choices=[1, 5], help="the n of the cases")
    ap.add_argument("--sine", type=int, default=3, help="sine-excitation cases (different data seeds)")
    ap.add_argument("--quick", action="store_true", help="2 rounds of 2,000 simulations (a try, not the benchmark)")
    ap.add_argument("--overrides", nargs="*", default=[], help="added to every run (e.g. policy=random)")
    ap.add_argument("--device", default="cpu", help="where the posterior models train (cpu, cuda)")
    ap.add_argument("--section", action="store_true",
                    help="print docs/results.md's section to stdout (progress to stderr): make results")
    ap.add_argument("--from-json", type=Path, help="render the rows a run wrote (foreign_dynamics.json) instead of running")
    args = ap.parse_args()
    progress = sys.stderr if args.section else sys.stdout
    if args.from_json:
        rows = json.loads(args.from_json.read_text())
    else:
        # worker processes that may start their own (each run draws its figures in one)
        with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            rows = []
            for row in pool.map(run_case, cases(args)):
                rows.append(row)
                print(table([row])[-1], file=progress, flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "foreign_dynamics.json").write_text(json.dumps(rows, indent=1))
    print(section(rows) if args.section else "\n".join(["", *summary(rows), "", *table(rows)]))


if __name__ == "__main__":
    main()

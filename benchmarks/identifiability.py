"""The identifiability report of a task's default run beside its posterior's contraction: what the summaries and the
collect policy can say about each parameter (diagnostics/identifiability.py) and what the posterior then learnt.

    PYTHONPATH=src python benchmarks/identifiability.py --task Cartpole --out /tmp/ident_cartpole
    PYTHONPATH=src python benchmarks/identifiability.py --task Pendulum --out /tmp/ident_pendulum rounds=1

Runs the task's default pipeline in --out (resumed where it stopped; extra arguments are overrides) and prints, per
parameter, round 1's held-out R^2 of the linear read, the local sensitivity at the nominal parameters (flagged: moves
nothing), and each round's contraction 1 - posterior variance / prior variance; then the pairs that act alike.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="Pendulum")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("overrides", nargs="*", help="added to the run (e.g. rounds=1 sim.nthread=1)")
    args = ap.parse_args()

    from bayessim_exp import api
    from bayessim_exp.diagnostics.identifiability import NO_EFFECT
    from bayessim_exp.pipeline import Pipeline

    cfg = api.compose([f"task={args.task}", f"seed={args.seed}", "sim=native", "logging.progress=false",
                       *args.overrides])
    Pipeline(cfg, args.out).run()
    rounds = json.loads((args.out / "results.json").read_text())["rounds"]
    first = rounds[0]["identifiability"]
    local = first["local"]
    print(f"{args.task}, seed {args.seed}, summarizer {cfg.summarizer.name}, policy {cfg.policy.name}, "
          f"{first['pairs']} held-out pairs, {local['trajectories'] if local else 0} local trajectories\n")
    head = "| parameter | R^2 (linear read) | local sensitivity | " + " | ".join(
        f"contraction round {r['round']}" for r in rounds) + " |"
    print(head + "\n|---|" + "---:|" * (head.count("|") - 2))
    for name in first["r2"]:
        sens = "-" if local is None else f"{local['rms'][name]:.3g}" + (" (no effect)" if local["rms"][name] < NO_EFFECT
                                                                       else "")
        print(f"| {name} | {first['r2'][name]:+.2f} | {sens} | "
              + " | ".join(f"{r['contraction'][name]:+.3f}" for r in rounds) + " |")
    for entry in [] if local is None else local["collinear"]:
        print(f"\nact alike at the nominal: {entry['pair'][0]} and {entry['pair'][1]} (cosine {entry['cosine']:+.3f}, "
              f"collinearity index {entry['index']:.0f})")
    for entry in first["trade_offs"]:
        print(f"\ntold apart only in part: {entry['pair'][0]} and {entry['pair'][1]} (held-out prediction errors "
              f"correlate {entry['correlation']:+.2f})")


if __name__ == "__main__":
    main()

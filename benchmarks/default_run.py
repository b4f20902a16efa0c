"""Wall time of whole runs, `python -m bayessim_exp`, as a newcomer starts them: variants interleaved.

    python benchmarks/default_run.py [--reps 3] [--warmup 1]
        [--variant gpu device=cuda] [--variant cpu device=cpu sim=native] [--src old=PATH] [--profile DIR]
        [--keep DIR] [-- OVERRIDES]

Each `--variant NAME OVERRIDE...` is a set of Hydra overrides (the first is the baseline; default: one
variant `default` with none); `--src NAME=PATH` adds, per variant, a copy run with PATH first on
PYTHONPATH (another checkout's `src`, copied with `cp -rL`: `src/bayessim_exp/conf` is a link), to
compare code. OVERRIDES after `--` go to every run. Every variant runs `--warmup` untimed runs first
(JAX's, MuJoCo Warp's and the trace caches filled), then the timed ones in turn, so a machine's drift
spreads over all. Per run: the wall time, the stages' seconds from results.json summed over the rounds,
the rest (imports, set-up, exit) and the last round's gain; then medians, and the wall time against the
baseline's. `--profile DIR` runs the timed runs under cProfile and `-X importtime` (DIR/<variant>_<run>.prof and
.imports: where the time outside the stages goes); their wall times then include the profiler's overhead.
`--keep DIR` keeps every run's directory there (results.json: what each round proposed from and handed on).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STAGES = ("collect", "summarize", "fit", "condition", "model_check", "guard", "score")


def timed_run(overrides: list[str], src: str | None, run_dir: Path, profile: Path | None = None) -> dict:
    """One run's wall time and stage seconds; with `profile` (a path without suffix) also its cProfile and its
    `-X importtime` log beside it."""
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.pathsep.join([src, *filter(None, [env.get("PYTHONPATH")])])
    profiler = ["-X", "importtime", "-m", "cProfile", "-o", f"{profile}.prof"] if profile else []
    shutil.rmtree(run_dir, ignore_errors=True)  # a run resumes from the stage files it finds (--keep's from before)
    cmd = [sys.executable, *profiler, "-m", "bayessim_exp", *overrides, f"hydra.run.dir={run_dir}",
           "logging.progress=false"]
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if profile:
        Path(f"{profile}.imports").write_text(done.stderr)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    rounds = json.loads((run_dir / "results.json").read_text())["rounds"]
    seconds = {s: sum(r["seconds"].get(s, 0.0) for r in rounds) for s in STAGES}
    stages = sum(sum(r["seconds"].values()) for r in rounds)
    return {"wall": wall, "stages": stages, "outside": wall - stages, **seconds, "gain": rounds[-1]["log_prob_gain"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--variant", nargs="+", action="append", metavar=("NAME", "OVERRIDE"),
                    help="a name, then its Hydra overrides; the first variant is the baseline")
    ap.add_argument("--src", action="append", default=[], metavar="NAME=PATH", help="also run each variant with PATH on PYTHONPATH")
    ap.add_argument("--json", help="write every run's figures here")
    ap.add_argument("--keep", type=Path, help="keep the runs' directories in this folder (default: a temporary one)")
    ap.add_argument("--profile", type=Path, help="profile the timed runs into this folder (cProfile, -X importtime)")
    ap.add_argument("common", nargs="*", help="overrides for every run (after --)")
    args = ap.parse_args()
    variants = [(v[0], v[1:], None) for v in (args.variant or [["default"]])]
    for spec in args.src:
        label, _, path = spec.partition("=")
        variants += [(f"{name}@{label}", overrides, str(Path(path).resolve())) for name, overrides, _ in variants
                     if "@" not in name]
    runs: dict[str, list[dict]] = {name: [] for name, _, _ in variants}
    if args.profile:
        args.profile.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or scratch
        for rep in range(-args.warmup, args.reps):
            for k, (name, overrides, src) in enumerate(variants):
                profile = args.profile / f"{name}_{rep + 1}" if args.profile and rep >= 0 else None
                result = timed_run([*overrides, *args.common], src, Path(tmp) / f"{k}_{rep + args.warmup}", profile)
                if rep >= 0:
                    runs[name].append(result)
                print(f"{'warm-up' if rep < 0 else f'run {rep + 1}'} {name}: {result['wall']:.1f} s "
                      f"(stages {result['stages']:.1f} s), gain {result['gain']}", flush=True)
    base = statistics.median(r["wall"] for r in runs[variants[0][0]])
    print(f"\n{args.reps} timed runs per variant after {args.warmup} warm-up; medians, seconds (stages summed over rounds)")
    print(f"{'variant':<28}{'wall':>7}{'min-max':>13}{'stages':>8}" + "".join(f"{s:>12}" for s in STAGES)
          + f"{'outside':>9}{'gain':>8}{'vs base':>9}")
    for name, results in runs.items():
        med = {key: statistics.median(r[key] for r in results) for key in ("wall", "stages", "outside", *STAGES)}
        walls = [r["wall"] for r in results]
        gains = {r["gain"] for r in results}
        gain = f"{results[-1]['gain']:+.2f}" if len(gains) == 1 and results[-1]["gain"] is not None else "varies"
        print(f"{name:<28}{med['wall']:>7.1f}{f'{min(walls):.1f}-{max(walls):.1f}':>13}{med['stages']:>8.1f}"
              + "".join(f"{med[s]:>12.1f}" for s in STAGES) + f"{med['outside']:>9.1f}{gain:>8}{med['wall'] / base:>8.2f}x")
    if args.json:
        Path(args.json).write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()

"""Is sim=auto at least as fast as native MuJoCo? Reads the `--json` file of benchmarks/sim_throughput.py
(rows native and mjx of a GPU machine) and prints, per task and MJX implementation, both rates, what sim=auto
picks there with the current tuning (sim/auto.py's auto_choice: the decision its simulator factory makes, from
conf/mjx_tuning's `native_faster_on`), whether auto is then at least as fast as native, and whether the tuning
picks the faster one:

    python benchmarks/auto_choice.py auto_table.json

benchmarks/device/gpu_benchmarks.sh auto_table measures Humanoid, Ant and ShadowHand and prints this table.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Mapping
from typing import Any

from bayessim_exp import api
from bayessim_exp.sim.auto import auto_choice

HEADER = ("task", "implementation", "envs", "native env-steps/s", "MJX env-steps/s", "sim=auto picks",
          "auto >= native?", "tuning")


def table(rows: list[dict], tuning_of: Callable[[str], Mapping[str, Any]]) -> list[tuple[str, ...]]:
    """A line per mjx row whose task has a native row; failed rows are named."""
    lines = []
    for row in rows:
        if "error" in row:
            lines.append((row["task"], "", "", "", "", "", "", f"FAILED: {row['error'][:80]}"))
        if row.get("backend") != "mjx" or row.get("env_steps_per_s") is None:
            continue
        native = next((r["env_steps_per_s"] for r in rows if r.get("task") == row["task"]
                       and r.get("backend") == "native" and r.get("env_steps_per_s")), None)
        if native is None:
            continue
        impl, mjx = row["impl"], row["env_steps_per_s"]
        picks = auto_choice(impl, tuning_of(row["task"]))
        auto = native if picks == "native" else mjx
        faster = "native" if native > mjx else "mjx"
        verdict = ("right" if picks == faster else
                   f"add {impl} to native_faster_on" if faster == "native" else f"drop {impl} from native_faster_on")
        lines.append((row["task"], impl, f"{row['envs']:,}", f"{native:,.0f}", f"{mjx:,.0f}",
                      "native" if picks == "native" else f"MJX ({impl})", "yes" if auto >= native else "no", verdict))
    return lines


def markdown(lines: list[tuple[str, ...]]) -> str:
    out = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    return "\n".join(out + ["| " + " | ".join(line) + " |" for line in lines])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("json", help="benchmarks/sim_throughput.py's --json output")
    args = ap.parse_args(argv)
    with open(args.json) as f:
        measured = json.load(f)
    overrides = measured.get("overrides", [])

    def tuning_of(task: str) -> Mapping[str, Any]:  # the task's tuning as sim=auto composes it
        return api.compose([f"task={task}", "sim=auto", *overrides]).sim.tuning

    print(f"device {measured.get('device', '?')}, sim_throughput.py --impl {measured.get('impl', '?')}")
    print(markdown(table(measured["rows"], tuning_of)))


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# The known-bias study of docs/statistics.md ('A summary error model'): benchmarks/summary_bias.py at four truths,
# each with two state features offset (never the initial state's or an action's: the replays hold those fixed),
# offsets 0, 0.2 and 0.5 of the features' prior spread, with and without the error model. One JSON line per run.
#   bash benchmarks/summary_bias_study.sh OUT_DIR     (about 12 minutes on one core)
set -euo pipefail
out=${1:?usage: summary_bias_study.sh OUT_DIR}
mkdir -p "$out"
cd "$(dirname "$0")/.."
for case in "1.3 0.6|5 20" "0.8 0.9|10 33" "1.7 0.45|4 47" "1.0 0.75|15 44"; do
  truth=${case%|*}; features=${case#*|}
  for offset in 0 0.2 0.5; do
    for mode in replays none; do
      name="${truth// /_}_${offset}_${mode}"
      OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/summary_bias.py --out "$out/$name" --truth $truth \
        --features $features --offset "$offset" --overrides "method.summary_error=$mode" 2>"$out/$name.log" \
        | tail -1 | tee -a "$out/study.jsonl"
    done
  done
done

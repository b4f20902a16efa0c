#!/usr/bin/env bash
# The trust issue's device studies side by side on one lent machine of 32 cores (nvidia-h100-x2) or more, after
# gpu_benchmarks.sh's installation, in the background so that they outlast a call:
#
#   COMMIT=<sha> OMP_NUM_THREADS=1 bash benchmarks/device/gpu_benchmarks.sh background exec \
#       bash benchmarks/device/trust_studies.sh
#   sleep 540; bash benchmarks/device/gpu_benchmarks.sh collect      # repeated, each call right after the last
#
# 1. every round's held-out coverage on all 11 tasks (benchmarks/round_coverage.py, seed 0, ROUND_JOBS runs
#    of sim.nthread=3 at once, on the first GPU; ROUND_JOBS=0 leaves it out);
# 2. known-truth studies of the tasks in STUDIES, "TASK:FIRST:LAST:JOBS[:SWEEP]" each (seeds FIRST..LAST-1, JOBS
#    runs of one simulation thread at once; SWEEP: calibration, the default, drawing the truths from the prior, or
#    nominal, sweeps/nominal.yaml's truths at and near the MJCF's values); the first study fits on the last GPU,
#    each later one on the GPU before (round robin), so that a study split into seed ranges spreads its fits
#    over the GPUs; the first study runs at normal priority, the later ones under `nice` so that they take what
#    the others leave. STUDY_ARGS: Hydra overrides for every study's runs (e.g. method.calibrate_on=all).
# Logs go to $OUT (gpu_benchmarks.sh's background folder); each study's run directories to
# /tmp/calibration_<task>_<first> (nominal: /tmp/calibration_nominal_<task>_<first>), which `collect` tars with how
# many runs finished. A seed is a truth: a study that repeats seeds an earlier one finished measures those truths
# twice (docs/benchmarks.md lists the seeds run). Each run keeps more than its one simulation thread busy (34 runs on
# 32 cores kept a load average near 170 on 2026-11-28): fewer JOBS than cores.
set -u
cd "$(dirname "$0")/../.."
OUT=${OUT:-$PWD/device_out}
mkdir -p "$OUT"
gpus=$(nvidia-smi -L | wc -l)

if [ "${ROUND_JOBS:-5}" -gt 0 ]; then
    CUDA_VISIBLE_DEVICES=0 python3 benchmarks/round_coverage.py --jobs "${ROUND_JOBS:-5}" --out /tmp/round_coverage \
        --json "$OUT/round_coverage.json" -- device=cuda sim=native sim.nthread=3 >"$OUT/round_coverage.log" 2>&1 &
fi

niceness=0
gpu=$((gpus - 1))
for study in ${STUDIES:-FrankaCabinet:0:50:12 ShadowHand:20:50:10}; do
    IFS=: read -r task first last jobs sweep <<<"$study"
    sweep=${sweep:-calibration}
    name=calibration_${task}_$first
    [ "$sweep" = calibration ] || name=calibration_${sweep}_${task}_$first
    CUDA_VISIBLE_DEVICES=$gpu nice -n "$niceness" python3 -m bayessim_exp --config-dir sweeps \
        --config-name "$sweep" --multirun device=cuda "task=$task" "seed=range($first,$last)" sim=native \
        sim.nthread=1 hydra/launcher=local "hydra.launcher.n_jobs=$jobs" "hydra.sweep.dir=/tmp/$name" ${STUDY_ARGS:-} \
        >"$OUT/$name.log" 2>&1 &
    niceness=10
    gpu=$(((gpu + gpus - 1) % gpus))
done
wait
echo "trust studies finished $(date -u +%H:%M:%S)"

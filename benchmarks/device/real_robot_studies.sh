#!/usr/bin/env bash
# Real systems in the prior's tail (docs/benchmarks.md, "Rounds that escape and focus"), on a lent machine of 64 cores
# and 4 GPUs (nvidia-h100-x4), after gpu_benchmarks.sh's installation, in the background so that they outlast a call:
#
#   COMMIT=<sha> OMP_NUM_THREADS=1 bash benchmarks/device/gpu_benchmarks.sh background exec \
#       bash benchmarks/device/real_robot_studies.sh
#   bash benchmarks/device/real_robot_studies.sh wait 540; bash benchmarks/device/real_robot_studies.sh collect
#                                                                      # repeated, each call right after the last
#
# Sweeps, each into /tmp/real_robot_studies/<name> (round records in results.json, written after every round):
# - franka_<escape>: FrankaCabinet at its own real_params (BayesSimIG's robot, in the prior's joint tail), seeds 0-2;
# - shadow_<escape>: ShadowHand with every link mass at the MJCF's value (multiplier 1: what a real hand most likely
#   is, |u|^2 = 43 in probit space against 24 for a typical prior draw), its other real_params, seeds 0-2;
#   both once per method.escape in $ESCAPES (default: linear nearest);
# - mission_gpu, mission_cpu: the mission's command `task=ShadowHand summarizer=signatory`, on the GPU (sim=auto, the
#   default pysiglib) and on native MuJoCo with device=cpu ($MISSION_THREADS threads for simulation and fit, default 6);
# - nominal_<task>: sweeps/nominal.yaml on the tasks in $NOMINAL ("TASK:SEEDS:JOBS", default Pendulum:50:10
#   Cartpole:20:6).
# $STUDIES picks among franka, shadow, mission (both missions; mission_gpu or mission_cpu alone) and nominal
# (default: all four).
# Every BayesSim fit runs on a GPU (device=cuda, round robin), every simulation natively on $THREADS threads.
# `wait SECONDS` returns when no sweep is left running or after SECONDS, whichever is first (a lease's device time
# counts while a fixed sleep outlasts the runs: on one H200 the real robots finished in 8 of 17 minutes slept).
# `collect` tars the run directories' results into $OUT/real_robot_studies.tar.gz and prints
# benchmarks/real_robot_rounds.py's table of each sweep (what each round proposed from, its guard, the gain at the truth).
set -u
cd "$(dirname "$0")/../.."
WORK=/tmp/real_robot_studies
OUT=${OUT:-$PWD/device_out}
PY=${PY:-python3}
mkdir -p "$OUT"

if [ "${1:-}" = wait ]; then
    for _ in $(seq "${2:-540}"); do
        pgrep -f "hydra.sweep.dir=$WORK/" >/dev/null || exit 0
        sleep 1
    done
    exit 0
fi

if [ "${1:-}" = collect ]; then
    for log in "$WORK"/*.log; do [ -f "$log" ] && { echo "== ${log##*/}"; tail -n 3 "$log"; }; done
    PYTHONPATH=/tmp/site:$PWD/src "$PY" benchmarks/real_robot_rounds.py "$WORK"/*/ | tee "$OUT/real_robot_rounds.md"
    # .hydra/config.yaml holds the rounds configured: without it the report counts a run cut short as finished
    (cd /tmp && tar -czf "$OUT/real_robot_studies.tar.gz" real_robot_studies/*.log real_robot_studies/*/*/results.json \
        real_robot_studies/*/*/.hydra/overrides.yaml real_robot_studies/*/*/.hydra/config.yaml \
        real_robot_studies/*/*/error.txt 2>/dev/null)
    exit 0
fi

mkdir -p "$WORK"
gpus=$(nvidia-smi -L | wc -l)
gpu=0
THREADS=${THREADS:-2}
sweep() {  # sweep NAME ARGS...: a --multirun into $WORK/NAME, fitting on the next GPU
    local name=$1
    shift
    CUDA_VISIBLE_DEVICES=$gpu "$PY" -m bayessim_exp --multirun "$@" hydra/launcher=local "hydra.sweep.dir=$WORK/$name" \
        logging.progress=false >"$WORK/$name.log" 2>&1 &
    gpu=$(((gpu + 1) % gpus))
}
masses=$("$PY" -c "from bayessim_exp.api import compose
print(' '.join(f'task.real_params.{n}=1.0' for n in compose(['task=ShadowHand']).task.parameters if n.startswith('mass_')))")

STUDIES=" ${STUDIES:-franka shadow mission nominal} "
studied() { [[ $STUDIES == *" $1 "* || ($1 == mission_* && $STUDIES == *" mission "*) ]]; }
for escape in ${ESCAPES:-linear nearest}; do
    studied franka && sweep "franka_$escape" task=FrankaCabinet seed=0,1,2 "method.escape=$escape" device=cuda sim=native \
        "sim.nthread=$THREADS" hydra.launcher.n_jobs=3
    # shellcheck disable=SC2086
    studied shadow && sweep "shadow_$escape" task=ShadowHand $masses seed=0,1,2 "method.escape=$escape" device=cuda sim=native \
        "sim.nthread=$THREADS" hydra.launcher.n_jobs=3
done
studied mission_gpu && sweep mission_gpu task=ShadowHand summarizer=signatory device=cuda seed=0 hydra.launcher.n_jobs=1
studied mission_cpu && OMP_NUM_THREADS=${MISSION_THREADS:-6} sweep mission_cpu task=ShadowHand summarizer=signatory sim=native \
    "sim.nthread=${MISSION_THREADS:-6}" seed=0 hydra.launcher.n_jobs=1
studied nominal || NOMINAL=" "
for study in ${NOMINAL:-Pendulum:50:8 Cartpole:20:6}; do
    IFS=: read -r task seeds jobs <<<"$study"
    sweep "nominal_$task" --config-dir sweeps --config-name nominal "task=$task" "seed=range($seeds)" device=cuda \
        sim=native sim.nthread=1 "hydra.launcher.n_jobs=$jobs"
done
wait
echo "real robot studies finished $(date -u +%H:%M:%S)"

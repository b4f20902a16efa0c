#!/usr/bin/env bash
# docs/benchmarks.md's GPU figures for the current code, on a lent GPU machine (NVIDIA H100, Python 3.12 with
# torch and jax preinstalled, no package registry). Installs the wheels carried in .whl/ into /tmp/site (and
# MuJoCo Warp when its parts came up, benchmarks/device/README.md), compiles bytecode, then runs the steps named:
#
#   bash benchmarks/device/gpu_benchmarks.sh [STEP...]      (no STEP: tests model_fit default_run throughput)
#   bash benchmarks/device/gpu_benchmarks.sh exec COMMAND...  any command after the same installation
#
# Steps:
#   tests        the MJX tests (whole files: they are marked slow, so no -k "not slow") and the GPU model tests;
#                fails unless tests of test_mjx.py and test_mjx_constants.py really passed
#   suite        make test's CPU lane (-m "not mjx") on the machine's CPUs, $SUITE_JOBS workers (default 8), run alone:
#                beside the real-robot studies on 2026-11-27 the load average passed 300 (issue 45)
#   model_fit    python benchmarks/model_fit.py --epochs 10
#   studies      benchmarks/device/trust_studies.sh's studies of $STUDIES (ROUND_JOBS default 0), left running in the
#                background after the step (after `missions`: runs beside them are no timings)
#   missions     issue 45's table: the mission's command, a cold run then a timed one, and ShadowHand_more's default
#                run twice (its first run after the mission's, then warm), on the first GPU; results.json of each run
#                and the timings' JSON into $OUT
#   default_run  python benchmarks/default_run.py: `device=cuda` ($REPS timed runs after one warm-up), then
#                `device=cpu sim=native` (one run)
#   throughput   python benchmarks/sim_throughput.py, Pendulum and Cartpole at 131,072 environments
#   throughput16k  the same for Ant, BallBalance, Ingenuity and Quadcopter at 16,384
#   humanoid     python -m bayessim_exp experiment=gpu_humanoid device=cuda, twice (cold, then warm)
#   auto_table   sim=auto against native MuJoCo (issue 29): benchmarks/sim_throughput.py for Humanoid, Ant and
#                ShadowHand on MJX's JAX implementation (the gpu extra) and native on all CPU threads, 4,096
#                environments x 50 steps; then benchmarks/auto_choice.py's table ($OUT/auto_table.json)
#   rl_gpu       benchmarks/rl.py on the GPU (issue 29): Cartpole and Ant, PPO with the compiled collection and
#                with torchrl's stepwise Collector, 8,192 environments x 16 steps, 5 epochs of minibatches of
#                32,768, once per MJX implementation in $RL_IMPLS (default "jax warp"; warp only where it came up);
#                Cartpole's run to 95 % of the maximum return with 2,048 x 32 and 5 epochs of 16,384, the
#                fastest of the settings tried (docs/benchmarks.md) ($OUT/rl_gpu_<impl>.json)
#   rl_cpu       benchmarks/rl.py on the machine's CPUs: native MuJoCo, the tasks' own PPO settings ($OUT/rl_cpu.json)
#   stash-warp   only keeps the Warp parts carried in this call (.warp/*/) for a later call on the same machine
#   calibration  the known-truth calibration study: sweeps/calibration.yaml (seed=range($SEEDS), default 100) on
#                each task of $CAL_TASKS (default Pendulum) in turn, with device=cuda and $CALIBRATION_ARGS, $JOBS
#                runs at once (default 6), each task's sweep stopped after $SWEEP_TIMEOUT seconds; then its report,
#                tarred into $OUT/calibration_<task>.tar.gz
#   round_coverage  benchmarks/round_coverage.py: every task's (or $TASKS') default run, seed 0 (or $ROUND_SEEDS),
#                and the runs $ROUND_ALSO (TASK:SEED ...), device=cuda and $ROUND_ARGS (e.g. sim=native), $JOBS at once
#   foreign      benchmarks/foreign_dynamics.py, 14 runs at once simulating on the CPUs, fitting on the GPU
#   results      benchmarks/results.py --jobs 14 (docs/results.md and its figure, copied into $OUT)
#   robots       benchmarks/results.py's GPU sections (issue 29: Ant and Humanoid, posterior / prior / nominal PPO),
#                $JOBS processes at once (default 16), $PER_GPU of them per GPU (default 4), work in
#                /tmp/robots_work (RESUME=1: resume what is there), after Warp's kernels are compiled by one
#                process; docs/results.md and the figures into $OUT
#
#   background STEP...  the steps, started in their own process session so that they outlast this call (a warm
#                machine keeps them running until it goes back): their logs and files go to /tmp/background_out
#   collect      what the background steps have written so far (their logs' tails printed) and the run directories
#                of studies under /tmp/calibration_* (results, configs, errors), with how many runs finished every
#                round (results.json is rewritten after each), in one $OUT/collected.tar.gz; the robots step's
#                finished jobs (their JSON, generated.json and logs) as $OUT/robots_work.tar.gz, for --resume or
#                --render-only here
#
# Logs and JSON go to $OUT (./device_out where OUT is unset), one log per step, each headed by the commit, the
# machine and the date. Every step runs even when an earlier one failed; the exit status is 1 if any failed.
# Environment: COMMIT (stamped where the copy has no .git), REPS (default 3), BYTECODE=0 (no compileall, as the
# measurements before 2026-11-22 23:39 UTC), STEP_TIMEOUT (seconds per step, default 540).
set -uo pipefail

cd "$(dirname "$0")/../.."
PY=${PYTHON:-python3}
OUT=${OUT:-$PWD/device_out}
SITE=${SITE:-/tmp/site}
WARP_PARTS=/tmp/warp_parts
mkdir -p "$OUT"
export PY OUT PYTHONPATH="$SITE:$PWD/src" PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false

say() { echo "[gpu_benchmarks $(date -u +%H:%M:%S)] $*"; }

install_wheels() {
    local stamp
    stamp=$(ls .whl/*.whl 2>/dev/null | xargs -r -n1 basename | sort | sha256sum | cut -c1-16)
    if [ -f "$SITE/.installed" ] && [ "$(cat "$SITE/.installed")" = "$stamp" ]; then
        say "wheels already installed in $SITE"
    elif ls .whl/*.whl >/dev/null 2>&1; then
        say "installing $(ls .whl/*.whl | wc -l) wheels into $SITE"
        "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/*.whl \
            || return 1
        echo "$stamp" >"$SITE/.installed"
    fi
    "$PY" -c "import mujoco, mujoco.mjx, hydra, torchrl" || { say "packages missing: carry .whl (benchmarks/device/README.md)"; return 1; }
}

# warp-lang goes up in parts over two calls to one warm machine (README.md); install once every part is here
install_warp() {
    mkdir -p "$WARP_PARTS"
    cp -n .warp/*/warp.tar.xz.* .warp/*/SHA256SUMS "$WARP_PARTS"/ 2>/dev/null
    [ -f "$WARP_PARTS/SHA256SUMS" ] || return 0
    [ -d "$SITE/warp" ] && return 0
    if ! (cd "$WARP_PARTS" && sha256sum --quiet -c SHA256SUMS >/dev/null 2>&1); then
        say "Warp: $(ls "$WARP_PARTS" | grep -c 'tar.xz') of $(wc -l <"$WARP_PARTS/SHA256SUMS") parts here; not installed yet"
        return 0
    fi
    say "installing warp-lang from its parts"
    cat "$WARP_PARTS"/warp.tar.xz.* | "$PY" -c "import sys, tarfile
tarfile.open(fileobj=sys.stdin.buffer, mode='r|xz').extractall('$SITE', filter='data')" || return 1
}

compile_bytecode() {
    [ "${BYTECODE:-1}" = 0 ] && { say "bytecode not compiled (BYTECODE=0)"; return 0; }
    [ -f "$SITE/.compiled" ] && return 0
    # the image sets PYTHONDONTWRITEBYTECODE=1 and ships no .pyc: every process would compile its imports
    say "compiling bytecode"
    "$PY" -m compileall -q -j 16 "$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" "$SITE" src \
        >/dev/null 2>&1  # some packages ship files that do not compile (templates, Python 2 tests): not an error here
    touch "$SITE/.compiled"
}

stamp() {
    local commit
    # COMMIT first: the copy's .git (where there is one) is the session's starting point, not the tree sent
    commit=${COMMIT:-$(git rev-parse --short HEAD 2>/dev/null || echo "unknown (set COMMIT)")}
    echo "commit: $commit"
    echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "machine: $(hostname), $(nproc) usable of $(grep -c ^processor /proc/cpuinfo) x $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
    echo "gpu: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo none)"
    "$PY" - <<'EOF'
import importlib.metadata as md
import sys
names = ["torch", "jax", "mujoco", "mujoco-mjx", "warp-lang", "hydra-core", "torchrl"]
versions = []
for name in names:
    try:
        versions.append(f"{name} {md.version(name)}")
    except md.PackageNotFoundError:
        versions.append(f"{name} -")
print(f"python {sys.version.split()[0]}; " + ", ".join(versions))
EOF
}

step_tests() {
    local xml=/tmp/gpu_tests.xml
    "$PY" -m pytest -q -rs -p no:cacheprovider --durations=15 --junitxml="$xml" \
        tests/unit/test_mjx.py tests/unit/test_mjx_constants.py tests/unit/test_mjx_tuning.py \
        tests/unit/test_trace_cache.py tests/unit/test_compiled_collection.py tests/unit/test_models.py tests/unit/test_adam.py \
        tests/unit/test_mixture_nll.py tests/unit/test_mdnn.py || return 1
    # a selection that deselects or skips every MJX test passes too: check that the MJX-against-native ones ran
    "$PY" - "$xml" <<'EOF'
import sys
import xml.etree.ElementTree as ET
passed = {"test_mjx_trajectories_match_native": 0, "test_device_leaves_equal_mujoco_set_const": 0}
for case in ET.parse(sys.argv[1]).iter("testcase"):
    name = case.get("name", "").split("[")[0]
    if name in passed and not any(c.tag in ("skipped", "failure", "error") for c in case):
        passed[name] += 1
print("MJX against native MuJoCo, cases passed:", passed)
sys.exit(0 if all(passed.values()) else 1)
EOF
}

# issue 45: the CPU lane of `make test` on this machine's CPUs (another CPU model than the development machine's),
# $SUITE_JOBS workers (default 8), each pinned by tests/conftest.py to its share of the CPUs; failures listed at the end
step_suite() {
    OMP_NUM_THREADS=1 "$PY" -m pytest -q -rfEs -p no:cacheprovider -n "${SUITE_JOBS:-8}" --dist loadgroup \
        --no-loadscope-reorder --max-worker-restart=0 --durations=60 -m "not mjx" tests
}

step_model_fit() { "$PY" benchmarks/model_fit.py --epochs 10; }

step_default_run() {
    "$PY" benchmarks/default_run.py --reps "${REPS:-3}" --warmup 1 --variant gpu device=cuda \
        --json "$OUT/default_run_gpu.json" || return 1
    "$PY" benchmarks/default_run.py --reps 1 --warmup 0 --variant cpu device=cpu sim=native \
        --json "$OUT/default_run_cpu.json"
}

step_throughput() {
    "$PY" benchmarks/sim_throughput.py --tasks Pendulum,Cartpole --envs 131072 --baseline-envs 131072 \
        --rows native,mjx-fixed,mjx --native-envs 8192 --horizon 50 --reps 5 --cache-dir /tmp/jax_cache \
        --json "$OUT/throughput_131072.json"
}

step_throughput16k() {
    "$PY" benchmarks/sim_throughput.py --tasks Ant,BallBalance,Ingenuity,Quadcopter --envs 16384 \
        --baseline-envs 16384 --rows native,mjx-fixed,mjx --native-envs 8192 --native-horizon 5 --horizon 50 \
        --reps 2 --cache-dir /tmp/jax_cache --json "$OUT/throughput_16384.json"
}

step_auto_table() {
    # 4,096 environments x 50 control steps: a default run's collect chunk and horizon (conf/config.yaml), the
    # batch its collect simulates on the GPU; one size and no mjx-fixed row, so each task's MJX compiles once
    "$PY" benchmarks/sim_throughput.py --tasks Humanoid,Ant,ShadowHand --impl jax --rows native,mjx --envs 4096 \
        --native-envs 4096 --horizon 50 --native-horizon 50 --reps 2 --cache-dir /tmp/jax_cache \
        --json "$OUT/auto_table.json" || return 1
    "$PY" benchmarks/auto_choice.py "$OUT/auto_table.json"
}

step_rl_gpu() {
    local rc=0 impl
    for impl in ${RL_IMPLS:-jax warp}; do
        if [ "$impl" = warp ] && ! "$PY" -c "import warp" 2>/dev/null; then echo "warp-lang not here: no warp rows"; continue; fi
        echo "== sim.impl=$impl"
        "$PY" benchmarks/rl.py --tasks Cartpole Ant --steps 2097152 --stepwise-steps 262144 --solve-steps 4194304 \
            --json "$OUT/rl_gpu_$impl.json" --overrides sim=mjx device=cuda "sim.impl=$impl" sim.cache_dir=/tmp/jax_cache \
            rl.train.num_envs=8192 rl.train.rollout_steps=16 rl.train.minibatch_size=32768 rl.train.epochs=5 \
            --solve-overrides rl.train.num_envs=2048 rl.train.rollout_steps=32 rl.train.minibatch_size=16384 || rc=1
    done
    return $rc
}

step_rl_cpu() {
    OMP_NUM_THREADS=1 "$PY" benchmarks/rl.py --tasks Cartpole Ant --json "$OUT/rl_cpu.json" --overrides sim=native
}

step_humanoid() {
    "$PY" -m bayessim_exp experiment=gpu_humanoid device=cuda logging.progress=false \
        hydra.run.dir=/tmp/humanoid_cold || return 1
    "$PY" -m bayessim_exp experiment=gpu_humanoid device=cuda logging.progress=false hydra.run.dir=/tmp/humanoid_warm
}

step_calibration() {  # the jobs finished within SWEEP_TIMEOUT come back, with their report
    local rc=0 task dir
    for task in ${CAL_TASKS:-Pendulum}; do
        dir=calibration_$task
        rm -rf "/tmp/$dir"  # an earlier call's jobs on the same warm machine would join the report
        timeout "${SWEEP_TIMEOUT:-480}" "$PY" -m bayessim_exp --config-dir sweeps --config-name calibration --multirun \
            device=cuda "task=$task" "seed=range(${SEEDS:-100})" hydra/launcher=local \
            "hydra.launcher.n_jobs=${JOBS:-6}" "hydra.sweep.dir=/tmp/$dir" ${CALIBRATION_ARGS:-} || rc=1
        "$PY" -m bayessim_exp.report "/tmp/$dir"
        (cd /tmp && tar -czf "$OUT/$dir.tar.gz" "$dir"/report "$dir"/*/results.json "$dir"/*/config.yaml \
            "$dir"/*/.hydra "$dir"/*/error.txt 2>/dev/null)
    done
    return $rc
}

step_round_coverage() {
    "$PY" benchmarks/round_coverage.py --jobs "${JOBS:-4}" --out /tmp/round_coverage --json "$OUT/round_coverage.json" \
        ${TASKS:+--tasks $TASKS} ${ROUND_SEEDS:+--seeds $ROUND_SEEDS} ${ROUND_ALSO:+--also $ROUND_ALSO} \
        -- device=cuda ${ROUND_ARGS:-}
}

step_foreign() {
    "$PY" benchmarks/foreign_dynamics.py --jobs 14 --device cuda --out /tmp/foreign \
        && cp /tmp/foreign/foreign_dynamics.json "$OUT/"
}

step_results() {
    "$PY" benchmarks/results.py --jobs 14 && cp docs/results.md docs/figures/rl_posterior_vs_prior.* "$OUT/"
}

step_robots() {
    # MuJoCo Warp compiles its kernels into ~/.cache/warp at a process's first step: once here, not in 16 at once
    "$PY" benchmarks/sim_throughput.py --tasks Ant,Humanoid --impl warp --rows mjx --envs 64 --horizon 2 --reps 1 \
        --compile-only || return 1
    "$PY" benchmarks/results.py --jobs "${JOBS:-16}" --per-gpu "${PER_GPU:-4}" --work /tmp/robots_work \
        ${RESUME:+--resume} --sections rl_on_robots_gpu rl_on_robots_humanoid
    local rc=$?
    cp docs/results.md docs/figures/rl_on_robots_Ant.* docs/figures/rl_on_robots_Humanoid.* "$OUT/" 2>/dev/null
    return $rc
}

step_studies() {  # not waited for: `collect` brings their runs back
    OMP_NUM_THREADS=1 ROUND_JOBS=${ROUND_JOBS:-0} setsid bash benchmarks/device/trust_studies.sh \
        >"$OUT/trust_studies.log" 2>&1 </dev/null &
    echo "trust studies started: ${STUDIES:-the default of trust_studies.sh}"
}

step_missions() {  # before `studies`: runs beside them slow the cold run severalfold (benchmarks/device/README.md)
    local f mission=(task=ShadowHand summarizer=signatory device=cuda)
    CUDA_VISIBLE_DEVICES=0 "$PY" benchmarks/default_run.py --reps 1 --warmup 1 --keep /tmp/runs_mission \
        --json "$OUT/mission.json" --variant mission "${mission[@]}"
    # MuJoCo Warp's kernels are the mission's (the same hand); the first run compiles its own JAX traces
    CUDA_VISIBLE_DEVICES=0 "$PY" benchmarks/default_run.py --reps 2 --warmup 0 --keep /tmp/runs_more \
        --json "$OUT/more.json" --variant more task=ShadowHand_more device=cuda
    for f in /tmp/runs_mission/*/results.json /tmp/runs_more/*/results.json; do  # what each round proposed and handed on
        cp "$f" "$OUT/results_$(basename "$(dirname "$(dirname "$f")")")_$(basename "$(dirname "$f")").json"
    done
}

run_step() {  # run_step NAME: step_NAME logged to $OUT/NAME.log, stopped after STEP_TIMEOUT seconds
    local name=$1 log="$OUT/$1.log"
    { stamp; echo "step: $name"; echo; } >"$log"
    say "$name"
    timeout "${STEP_TIMEOUT:-540}" bash -c "$(declare -f "step_$name"); step_$name" >>"$log" 2>&1 </dev/null
    local rc=$?
    tail -n 40 "$log"
    if [ $rc = 0 ]; then say "$name: ok"; else say "$name: FAILED ($rc)"; fi
    return $rc
}

if [ "${1:-}" = stash-warp ] && [ $# = 1 ]; then  # the first Warp call carries no wheels
    install_warp
    exit $?
fi
BACKGROUND_OUT=/tmp/background_out
if [ "${1:-}" = collect ] && [ $# = 1 ]; then
    for log in "$BACKGROUND_OUT"/*.log; do [ -f "$log" ] && { say "${log##*/}"; tail -n 15 "$log"; }; done
    # A call brings back at most 8 files from $OUT (the device tool's limits): everything goes into one archive,
    # the background steps' outputs and the finished runs of each study started with `background exec`
    # (hydra.sweep.dir=/tmp/calibration_NAME)
    studies=()
    for dir in /tmp/calibration_*/; do
        dir=$(basename "$dir")
        [ -d "/tmp/$dir" ] || continue
        # results.json is rewritten after every round: count by status, as the report does (report/jobs.py)
        say "$dir: $("$PY" -c "import collections, sys; from bayessim_exp.report.jobs import read_jobs
print(', '.join(f'{n} {s}' for s, n in sorted(collections.Counter(j.status for j in read_jobs(sys.argv[1])).items())))" \
            "/tmp/$dir")"
        # the globs expand in /tmp, where tar runs: expanded here they matched nothing and the runs stayed behind
        mapfile -t -O "${#studies[@]}" studies < <(cd /tmp && shopt -s nullglob && printf '%s\n' "$dir"/report \
            "$dir"/*/results.json "$dir"/*/config.yaml "$dir"/*/.hydra "$dir"/*/error.txt)
    done
    (cd /tmp && tar -czf "$OUT/collected.tar.gz" "${BACKGROUND_OUT#/tmp/}" "${studies[@]}" 2>/dev/null)
    say "$OUT/collected.tar.gz: $(du -h "$OUT/collected.tar.gz" | cut -f1)"
    if [ -d /tmp/robots_work ]; then
        (cd /tmp/robots_work && tar -czf "$OUT/robots_work.tar.gz" logs */*.json 2>/dev/null)
        say "robots: $(ls /tmp/robots_work/*/*_seed*.json 2>/dev/null | wc -l) jobs finished or under way"
    fi
    exit 0
fi
if [ "${1:-}" = background ]; then  # the steps in a new session, after this call ends
    shift
    # installed here, so that a call that carried no wheels fails now (`background ... && sleep N` ends at once)
    install_wheels || exit 1
    install_warp || exit 1
    mkdir -p "$BACKGROUND_OUT"
    OUT=$BACKGROUND_OUT setsid nohup bash "$0" "$@" >"$BACKGROUND_OUT/background.log" 2>&1 </dev/null &
    say "started in the background: $* (bash $0 collect copies their outputs)"
    exit 0
fi
install_wheels || exit 1
install_warp || exit 1
compile_bytecode
"$PY" -c "import jax; d = jax.devices()[0]; print('JAX device:', d); assert d.platform == 'gpu'" \
    || { say "JAX sees no GPU"; exit 1; }

if [ "${1:-}" = exec ]; then
    shift
    { stamp; echo "command: $*"; echo; } | tee "$OUT/exec.log"
    "$@" 2>&1 | tee -a "$OUT/exec.log"
    exit "${PIPESTATUS[0]}"
fi

[ $# = 0 ] && set -- tests model_fit default_run throughput
failed=()
for step in "$@"; do
    case $step in
        stash-warp) ;;
        tests|suite|model_fit|default_run|studies|missions|throughput|throughput16k|humanoid|auto_table|rl_gpu|rl_cpu|calibration|round_coverage|foreign|results|robots)
            run_step "$step" || failed+=("$step") ;;
        *) say "unknown step: $step"; failed+=("$step") ;;
    esac
done
[ ${#failed[@]} = 0 ] || { say "failed: ${failed[*]}"; exit 1; }
say "all steps passed; outputs in $OUT"

#!/usr/bin/env bash
# A real one-node Slurm on this machine, for the Slurm launcher's end-to-end test and CI.
#   bash scripts/slurm_localhost.sh start    install (Debian packages), configure, start; exit 0 when a job can run
#   bash scripts/slurm_localhost.sh stop     stop the daemons this script started
#   bash scripts/slurm_localhost.sh status   exit 0 when the node takes jobs
# Needs root and Debian's apt. On failure the last line on stderr says why (tests skip with it).
set -uo pipefail

STATE=/var/lib/bayessim_slurm            # pid files and logs of the daemons started here
CONF=/etc/slurm/slurm.conf
NODE=$(hostname -s)

die() { echo "slurm_localhost: $*" >&2; exit 1; }

node_ready() {
  timeout 10 sinfo -h -N -o '%T' 2>/dev/null | grep -Eq '^(idle|mixed|allocated)'
}

install_packages() {
  command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v sbatch >/dev/null \
    && command -v munged >/dev/null && return 0
  command -v apt-get >/dev/null || die "no apt-get: not a Debian system, cannot install Slurm"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >"$STATE/apt.log" 2>&1 || die "apt-get update failed (see $STATE/apt.log)"
  # policy-rc.d 101: packages must not try to start services through an init system we may not have
  printf '#!/bin/sh\nexit 101\n' >/usr/sbin/policy-rc.d && chmod +x /usr/sbin/policy-rc.d
  apt-get install -y -qq --no-install-recommends munge slurmctld slurmd slurm-client >>"$STATE/apt.log" 2>&1
  local rc=$?
  rm -f /usr/sbin/policy-rc.d
  [ $rc -eq 0 ] || die "apt-get install munge slurmctld slurmd slurm-client failed (see $STATE/apt.log)"
}

MARK="# One-node Slurm on localhost, written by scripts/slurm_localhost.sh"

write_config() {
  local cpus mem_mb
  if [ -s "$CONF" ] && [ "$(head -n 1 "$CONF")" != "$MARK" ]; then
    die "$CONF exists and was not written by this script: not replacing a real cluster's config"
  fi
  cpus=$(nproc)
  mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 ))
  mkdir -p /etc/slurm "$STATE/ctld" "$STATE/d"
  # linuxproc/none plugins: no cgroups or accounting database needed (submitit reads job state from
  # its own result files when sacct has no database)
  cat >"$CONF" <<EOF
$MARK
ClusterName=localhost
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
# a requeued job waits cred_expire seconds before it may start again (default 120)
AuthInfo=cred_expire=10
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
JobRequeue=1
SlurmdTimeout=60
InactiveLimit=0
KillWait=5
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
}

start_munge() {
  timeout 5 munge -n 2>/dev/null | timeout 5 unmunge >/dev/null 2>&1 && return 0
  [ -s /etc/munge/munge.key ] || { mungekey --create >/dev/null 2>&1 || dd if=/dev/urandom of=/etc/munge/munge.key bs=1k count=1 2>/dev/null; }
  chown -R munge:munge /etc/munge /var/lib/munge /var/log/munge 2>/dev/null
  chmod 0400 /etc/munge/munge.key
  mkdir -p /run/munge && chown munge:munge /run/munge
  runuser -u munge -- munged >>"$STATE/munged.log" 2>&1 || die "munged did not start (see $STATE/munged.log)"
  touch "$STATE/munged.started"  # so that stop ends only a munged started here
  for _ in $(seq 20); do
    timeout 5 munge -n 2>/dev/null | timeout 5 unmunge >/dev/null 2>&1 && return 0
    sleep 0.5
  done
  die "munge credentials do not round-trip (see $STATE/munged.log)"
}

start() {
  [ "$(id -u)" -eq 0 ] || die "needs root (daemons and packages)"
  mkdir -p "$STATE"
  if node_ready; then echo "slurm_localhost: already running (node $NODE)"; exit 0; fi
  install_packages
  write_config
  start_munge
  pgrep -F "$STATE/slurmctld.pid" >/dev/null 2>&1 || slurmctld >>"$STATE/slurmctld.log" 2>&1 \
    || die "slurmctld did not start (see $STATE/slurmctld.log)"
  pgrep -F "$STATE/slurmd.pid" >/dev/null 2>&1 || slurmd >>"$STATE/slurmd.log" 2>&1 \
    || die "slurmd did not start (see $STATE/slurmd.log)"
  for _ in $(seq 60); do
    if node_ready; then
      timeout 60 srun -N1 -n1 -t 1 true >/dev/null 2>&1 || die "the node is up but a test job failed (see $STATE/slurmd.log)"
      echo "slurm_localhost: running (node $NODE, $(nproc) CPUs, partition debug)"
      exit 0
    fi
    sleep 1
  done
  scontrol update nodename="$NODE" state=resume >/dev/null 2>&1
  node_ready && { echo "slurm_localhost: running (node $NODE, resumed)"; exit 0; }
  die "node $NODE never became idle: $(tail -n 3 "$STATE/slurmd.log" 2>/dev/null | tr '\n' ' ')"
}

stop() {
  # only the daemons whose pid files this script's config names, and munged if this script started it
  for pidfile in "$STATE/slurmd.pid" "$STATE/slurmctld.pid"; do
    [ -s "$pidfile" ] && kill "$(cat "$pidfile")" 2>/dev/null
  done
  if [ -e "$STATE/munged.started" ] && [ -s /run/munge/munged.pid ]; then
    kill "$(cat /run/munge/munged.pid)" 2>/dev/null
    rm -f "$STATE/munged.started"
  fi
  echo "slurm_localhost: stopped"
}

case "${1:-start}" in
  start) start ;;
  stop) stop ;;
  status) node_ready && echo "slurm_localhost: running" || die "not running" ;;
  *) die "usage: $0 start|stop|status" ;;
esac

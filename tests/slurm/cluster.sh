#!/usr/bin/env bash
# A throw-away one-node Slurm cluster (munged + slurmctld + slurmd on this
# host) for tests/slurm_cluster.rs; run as root with slurm-wlm and munge
# installed. Nothing outside DIR is written or read besides the binaries.
#
#   cluster.sh start DIR [CTLD_PORT SLURMD_PORT]
#       writes DIR/slurm.conf, starts the three daemons (pids in DIR/*.pid),
#       waits until the node accepts jobs, and prints the line
#       `export SLURM_CONF=DIR/slurm.conf` for the client commands.
#   cluster.sh stop DIR
#       stops the daemons started in DIR, by their process ids.
set -euo pipefail

die() { echo "cluster.sh: $*" >&2; exit 1; }

stop() {
  local dir=$1 pid name
  for name in slurmd slurmctld munged; do
    [ -f "$dir/$name.pid" ] || continue
    pid=$(cat "$dir/$name.pid")
    kill -TERM "$pid" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    rm -f "$dir/$name.pid"
  done
}

start() {
  local dir ctld_port slurmd_port host cpus
  dir=$(cd "$1" && pwd)
  ctld_port=${2:-$((20000 + RANDOM % 20000))}
  slurmd_port=${3:-$((ctld_port + 1))}
  for t in munged slurmctld slurmd sbatch sinfo; do
    command -v "$t" >/dev/null || die "$t not found (apt-get install slurm-wlm munge)"
  done
  [ "$(id -u)" = 0 ] || die "must run as root (the daemons and jobs run as root)"
  host=$(hostname -s)
  cpus=$(nproc)
  mkdir -p "$dir/state" "$dir/spool" "$dir/munge"
  chmod 700 "$dir" "$dir/munge"

  # munge: a fresh key and its own socket, so a system munged is not touched.
  head -c 1024 /dev/urandom >"$dir/munge/munge.key"
  chmod 400 "$dir/munge/munge.key"
  munged --force --socket="$dir/munge/munge.socket" \
    --key-file="$dir/munge/munge.key" --pid-file="$dir/munge/munged.pid" \
    --log-file="$dir/munge/munged.log" --seed-file="$dir/munge/munged.seed"
  for _ in $(seq 50); do [ -s "$dir/munge/munged.pid" ] && break; sleep 0.1; done
  [ -s "$dir/munge/munged.pid" ] || die "munged did not start (see $dir/munge/munged.log)"
  cp "$dir/munge/munged.pid" "$dir/munged.pid"

  cat >"$dir/slurm.conf" <<CONF
ClusterName=camsimtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
ReturnToService=2
KillWait=2
MinJobAge=3600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF=$dir/slurm.conf
  # -D: no fork, so $! is the daemon; setsid + redirections: the caller's
  # pipes are not held open by the daemons.
  setsid slurmctld -D -i -f "$SLURM_CONF" >"$dir/slurmctld.out" 2>&1 </dev/null &
  echo $! >"$dir/slurmctld.pid"
  setsid slurmd -D -f "$SLURM_CONF" -N "$host" >"$dir/slurmd.out" 2>&1 </dev/null &
  echo $! >"$dir/slurmd.pid"
  local state=""
  for _ in $(seq 300); do
    state=$(sinfo -h -n "$host" -o %T 2>/dev/null || true)
    case "$state" in idle*|mixed*|allocated*) break ;; esac
    sleep 0.2
  done
  case "$state" in
    idle*|mixed*|allocated*) ;;
    *) stop "$dir"
       die "node did not become idle (state '$state'); see $dir/slurmctld.log and $dir/slurmd.log" ;;
  esac
  echo "export SLURM_CONF=$SLURM_CONF"
}

case "${1:-}" in
  start) [ $# -ge 2 ] || die "usage: cluster.sh start DIR [CTLD_PORT SLURMD_PORT]"; start "${@:2}" ;;
  stop)  [ $# -eq 2 ] || die "usage: cluster.sh stop DIR"; stop "$2" ;;
  *) die "usage: cluster.sh start DIR [CTLD_PORT SLURMD_PORT] | cluster.sh stop DIR" ;;
esac

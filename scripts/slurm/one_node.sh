#!/usr/bin/env bash
# A throwaway one-node Slurm cluster in a folder, for the test suite and for trying the scripts
# of this folder on one machine (Debian's slurm-wlm and munge; run as root).
#
#   scripts/slurm/one_node.sh start DIR   writes DIR/slurm.conf and a munge key, starts munged,
#                                         slurmctld and slurmd in the background (their pids in
#                                         DIR/pids), waits until the node is idle, and prints
#                                         the line to source: export SLURM_CONF=DIR/slurm.conf
#   scripts/slurm/one_node.sh stop DIR    stops the three daemons by the pids it started
#
# Nothing outside DIR is written: the daemons' state, spool, logs, pid files and munge socket
# live in DIR, on ports chosen from the free ones (SLURM_TEST_PORT overrides: it and the next
# port). The node offers the machine's CPUs and 90% of its memory; the partition is "debug".
# A requeued job starts again after cred_expire (10 s here, 120 s by default).
set -euo pipefail

usage() {
  echo "usage: one_node.sh start|stop DIR" >&2
  exit 2
}
[ $# -eq 2 ] || usage
action="$1"
dir="$2"

stop() {
  local pids="$dir/pids"
  [ -f "$pids" ] || return 0
  # slurmd first (it runs the jobs), then slurmctld, then munged.
  tac "$pids" | while read -r name pid; do
    if kill -0 "$pid" 2>/dev/null; then
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
      if kill -0 "$pid" 2>/dev/null; then
        echo "one_node.sh: $name (pid $pid) did not stop in 5 s: killing it" >&2
        kill -9 "$pid" 2>/dev/null || true
      fi
    fi
  done
  rm -f "$pids"
}

need() {
  for tool in "$@"; do
    if ! command -v "$tool" >/dev/null 2>&1 && [ ! -x "/usr/sbin/$tool" ]; then
      echo "one_node.sh: $tool is not installed (apt-get install slurm-wlm munge)" >&2
      exit 3
    fi
  done
}

free_port() {
  # Two consecutive ports nobody listens on, from a range Slurm's defaults do not use.
  local base
  for _ in $(seq 200); do
    base=$((20000 + RANDOM % 20000))
    if ! ss -Hltn "( sport = :$base or sport = :$((base + 1)) )" 2>/dev/null | grep -q .; then
      echo "$base"
      return
    fi
  done
  echo "one_node.sh: no free port pair found" >&2
  exit 3
}

start() {
  if [ "$(id -u)" -ne 0 ]; then
    echo "one_node.sh: the daemons run as root here (slurmd starts jobs as their user)" >&2
    exit 3
  fi
  need munged slurmctld slurmd sbatch sinfo
  export PATH="$PATH:/usr/sbin"
  mkdir -p "$dir"
  dir="$(cd "$dir" && pwd)"
  chmod 711 "$dir"
  mkdir -p "$dir/state" "$dir/spool" "$dir/munge"
  chmod 711 "$dir/munge"
  : >"$dir/pids"

  # munge: its own key and socket.
  dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge/munge.key"
  munged --foreground --force --socket="$dir/munge/socket" --key-file="$dir/munge/munge.key" \
    --log-file="$dir/munge/munged.log" --pid-file="$dir/munge/munged.pid" \
    --seed-file="$dir/munge/munged.seed" >"$dir/munge/munged.out" 2>&1 &
  echo "munged $!" >>"$dir/pids"
  for _ in $(seq 50); do [ -S "$dir/munge/socket" ] && break; sleep 0.1; done
  [ -S "$dir/munge/socket" ] || { echo "one_node.sh: munged did not start (log: $dir/munge/munged.log)" >&2; stop; exit 3; }

  local host cpus mem_mb port
  host="$(hostname -s)"
  cpus="$(nproc)"
  mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) * 9 / 10 / 1024 ))
  port="${SLURM_TEST_PORT:-$(free_port)}"
  cat >"$dir/slurm.conf" <<EOF
# A one-node cluster written by scripts/slurm/one_node.sh.
ClusterName=mesatest
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$dir/munge/socket,cred_expire=10
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  export SLURM_CONF="$dir/slurm.conf"
  slurmctld -D -i -f "$SLURM_CONF" >"$dir/slurmctld.out" 2>&1 &
  echo "slurmctld $!" >>"$dir/pids"
  slurmd -D -f "$SLURM_CONF" -N "$host" >"$dir/slurmd.out" 2>&1 &
  echo "slurmd $!" >>"$dir/pids"

  # Wait (at most 60 s) for the node to be idle.
  local state=""
  for _ in $(seq 120); do
    state="$(sinfo -h -N -o '%T' 2>/dev/null | head -1 || true)"
    [ "$state" = "idle" ] && break
    sleep 0.5
  done
  if [ "$state" != "idle" ]; then
    echo "one_node.sh: the node did not become idle (state \"$state\"); logs: $dir/slurmctld.log, $dir/slurmd.log" >&2
    tail -n 20 "$dir/slurmctld.log" "$dir/slurmd.log" >&2 2>/dev/null || true
    stop
    exit 3
  fi
  echo "export SLURM_CONF=$SLURM_CONF"
}

case "$action" in
  start) start ;;
  stop) stop ;;
  *) usage ;;
esac

#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for trying `inhand eval --backend slurm` and for its
# test: munged, slurmctld and slurmd on the loopback interface, every file (key, configuration,
# state, logs, process ids) in one directory, the daemons started and stopped by their process ids.
#
#   bash scripts/slurm-local.sh start    # prints the SLURM_CONF to export
#   bash scripts/slurm-local.sh status
#   bash scripts/slurm-local.sh stop
#
# Environment: INHAND_SLURM_DIR (default /tmp/inhand-slurm), INHAND_SLURM_PORT (slurmctld's port,
# default 6817; slurmd takes the next). Needs root (slurmd starts jobs as their user) and the
# packages slurmctld, slurmd, slurm-client and munge (INHAND_WITH_SLURM=1 scripts/install_deps.sh).
# When /etc/slurm/slurm.conf does not exist, `start` links it to this cluster's configuration (and
# `stop` removes that link), so that sbatch and squeue find the cluster without SLURM_CONF.
set -euo pipefail

dir="${INHAND_SLURM_DIR:-/tmp/inhand-slurm}"
port="${INHAND_SLURM_PORT:-6817}"
conf="$dir/slurm.conf"
etc_conf=/etc/slurm/slurm.conf

die() {
  echo "slurm-local: $*" >&2
  exit 1
}

alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2> /dev/null; }

stop_pid() {  # stop_pid NAME PIDFILE
  local pidfile="$2" pid
  [ -f "$pidfile" ] || return 0
  pid="$(cat "$pidfile")"
  if kill -0 "$pid" 2> /dev/null; then
    kill "$pid"
    for _ in $(seq 100); do
      kill -0 "$pid" 2> /dev/null || break
      sleep 0.1
    done
    if kill -0 "$pid" 2> /dev/null; then
      echo "slurm-local: $1 ($pid) did not stop in 10 s; killing it" >&2
      kill -9 "$pid" 2> /dev/null || true
    fi
  fi
  rm -f "$pidfile"
}

cmd_stop() {
  stop_pid slurmd "$dir/slurmd.pid"
  stop_pid slurmctld "$dir/slurmctld.pid"
  stop_pid munged "$dir/munged.pid"
  if [ -L "$etc_conf" ] && [ "$(readlink "$etc_conf")" = "$conf" ]; then rm -f "$etc_conf"; fi
  echo "slurm-local: stopped ($dir)"
}

cmd_status() {
  local up=0
  for d in munged slurmctld slurmd; do
    if alive "$dir/$d.pid"; then
      echo "$d: running (pid $(cat "$dir/$d.pid"))"
      up=$((up + 1))
    else
      echo "$d: not running"
    fi
  done
  [ "$up" -eq 3 ] && SLURM_CONF="$conf" sinfo
  [ "$up" -eq 3 ]
}

cmd_start() {
  [ "$(id -u)" -eq 0 ] || die "needs root (slurmd starts each job as its user)"
  for b in munged mungekey slurmctld slurmd sbatch squeue sinfo scontrol; do
    command -v "$b" > /dev/null ||
      die "$b not found: install Slurm with INHAND_WITH_SLURM=1 bash scripts/install_deps.sh"
  done
  if alive "$dir/slurmctld.pid" || alive "$dir/slurmd.pid" || alive "$dir/munged.pid"; then
    die "already running in $dir (bash scripts/slurm-local.sh stop first)"
  fi
  mkdir -p "$dir/state" "$dir/spool" "$dir/munge"
  chmod 0755 "$dir"
  chmod 0700 "$dir/munge"

  # MUNGE: a key of its own and a socket in the cluster's directory.
  [ -f "$dir/munge/munge.key" ] || mungekey --create --keyfile="$dir/munge/munge.key"
  chmod 0600 "$dir/munge/munge.key"
  munged --force --socket="$dir/munge/munge.socket" --key-file="$dir/munge/munge.key" \
    --pid-file="$dir/munged.pid" --log-file="$dir/munged.log" --seed-file="$dir/munge/munge.seed"
  for _ in $(seq 50); do
    [ -S "$dir/munge/munge.socket" ] && break
    sleep 0.1
  done
  [ -S "$dir/munge/munge.socket" ] || die "munged did not start (see $dir/munged.log)"

  # The node as slurmd sees it (CPUs, sockets, memory), reached on the loopback interface.
  local host node
  host="$(hostname -s)"
  node="$(slurmd -C | head -1)"
  [[ "$node" == NodeName=* ]] || die "slurmd -C printed no node description"
  cat > "$conf" << EOF
# Written by inhand's scripts/slurm-local.sh: a single-node cluster on the loopback interface.
ClusterName=inhand-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
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
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MaxArraySize=10001
MinJobAge=600
KillWait=10
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  # A link left by a cluster that is gone (its directory removed) is replaced.
  if [ -L "$etc_conf" ] && [ ! -e "$etc_conf" ]; then rm -f "$etc_conf"; fi
  if [ ! -e "$etc_conf" ] && [ -d "$(dirname "$etc_conf")" ]; then ln -s "$conf" "$etc_conf"; fi

  export SLURM_CONF="$conf"
  slurmctld -f "$conf" -c -i
  slurmd -f "$conf"
  for _ in $(seq 100); do
    if sinfo -h -o %t 2> /dev/null | grep -q '^idle'; then
      echo "slurm-local: running in $dir (slurmctld pid $(cat "$dir/slurmctld.pid"), slurmd pid" \
        "$(cat "$dir/slurmd.pid"), munged pid $(cat "$dir/munged.pid"))"
      if [ "$(readlink "$etc_conf" 2> /dev/null || true)" != "$conf" ]; then
        echo "slurm-local: $etc_conf belongs to another cluster; for this one: export SLURM_CONF=$conf"
      fi
      return 0
    fi
    sleep 0.2
  done
  sinfo >&2 || true
  tail -5 "$dir/slurmctld.log" "$dir/slurmd.log" >&2 || true
  cmd_stop > /dev/null
  die "the node did not come up in 20 s (logs in $dir)"
}

case "${1:-}" in
  start) cmd_start ;;
  stop) cmd_stop ;;
  status) cmd_status ;;
  *) die "usage: $0 start|stop|status" ;;
esac

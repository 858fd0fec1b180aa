#!/usr/bin/env bash
# Single-node SLURM on localhost (Debian slurm-wlm + munge) for tests/slurm/test_slurm_executor.py.
#
#   start_local_slurm.sh [start]   install (if missing), configure and start munged, slurmctld, slurmd
#   start_local_slurm.sh stop      stop the daemons this script started (by the pids it recorded)
#
# Idempotent: `start` returns at once when the partition already answers; packages are installed only
# when a binary is missing. No accounting daemon: finished jobs stay visible to `squeue --states=all`
# for MinJobAge seconds, which is what the executor plugin's `--slurm-status-command squeue` reads.
# Exit codes: 0 up/stopped, 2 not root, 3 packages missing and could not be installed, 4 a foreign
# /etc/slurm/slurm.conf exists (not overwritten), 1 the daemons did not come up.
set -euo pipefail

MARKER="# written by tissuemech tests/slurm/start_local_slurm.sh"
STARTED=/run/tissuemech-local-slurm.pids
CONF=/etc/slurm/slurm.conf

partition_state() {
  timeout 10 sinfo -h -o %t 2>/dev/null | head -1 || true
}

is_up() {
  local state
  # our own configuration but no controller: down (sinfo would retry for ~10 s)
  if [ -f "$CONF" ] && grep -qF "$MARKER" "$CONF" && ! pgrep -x slurmctld >/dev/null; then
    return 1
  fi
  state=$(partition_state)
  [ "$state" = "idle" ] || [ "$state" = "mix" ] || [ "$state" = "alloc" ]
}

stop() {
  [ -f "$STARTED" ] || { echo "nothing started by this script"; return 0; }
  # slurmd first so that the controller does not mark the node down while it drains
  for daemon in slurmd slurmctld munged; do
    pid=$(awk -v d="$daemon" '$1 == d {print $2}' "$STARTED")
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
      kill "$pid"
      for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    fi
  done
  rm -f "$STARTED"
  echo "slurm stopped"
}

start() {
  if is_up; then
    echo "slurm already running ($(partition_state))"
    return 0
  fi
  if [ "$(id -u)" -ne 0 ]; then
    echo "not root: cannot install or start SLURM" >&2
    return 2
  fi
  if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sinfo >/dev/null \
    || ! command -v munged >/dev/null; then
    if ! command -v apt-get >/dev/null; then
      echo "slurmctld/slurmd/munged missing and no apt-get to install them" >&2
      return 3
    fi
    export DEBIAN_FRONTEND=noninteractive
    if ! { apt-get update -qq -o DPkg::Lock::Timeout=120 && apt-get install -y -qq -o DPkg::Lock::Timeout=120 --no-install-recommends slurm-wlm munge; } \
      >/tmp/tissuemech-slurm-apt.log 2>&1; then
      echo "apt-get install slurm-wlm munge failed:" >&2
      tail -5 /tmp/tissuemech-slurm-apt.log >&2
      return 3
    fi
  fi
  if [ -f "$CONF" ] && ! grep -qF "$MARKER" "$CONF"; then
    echo "$CONF exists and was not written by this script: not overwriting a real cluster's configuration" >&2
    return 4
  fi

  mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge /var/lib/munge \
    /var/log/munge /etc/munge
  if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null
  fi
  chown -R munge:munge /etc/munge /run/munge /var/lib/munge /var/log/munge
  chmod 0700 /etc/munge
  chmod 0400 /etc/munge/munge.key
  : >>"$STARTED"
  if ! pgrep -x munged >/dev/null; then
    runuser -u munge -- /usr/sbin/munged
    for _ in $(seq 1 50); do [ -s /run/munge/munged.pid ] && break; sleep 0.1; done
    echo "munged $(cat /run/munge/munged.pid)" >>"$STARTED"
  fi

  # The node line comes from slurmd -C (real sockets/cores/threads); RealMemory keeps 1 GiB for the OS.
  local node mem_mb
  node=$(slurmd -C | head -1)
  mem_mb=$(( $(sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p' <<<"$node") - 1024 ))
  node=$(sed "s/RealMemory=[0-9]*/RealMemory=${mem_mb}/" <<<"$node")
  local host
  host=$(sed -n 's/^NodeName=\([^ ]*\).*/\1/p' <<<"$node")
  cat >"$CONF" <<CONF
${MARKER}
ClusterName=tissuemech-ci
SlurmctldHost=${host}(127.0.0.1)
AuthType=auth/munge
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
ReturnToService=2
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmdSpoolDir=/var/spool/slurmd
StateSaveLocation=/var/spool/slurmctld
SlurmUser=root
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
# jobs that ask for no memory get 1 GB per CPU, not the whole node
DefMemPerCPU=1000
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
MpiDefault=none
# finished jobs stay in slurmctld (and squeue --states=all) for an hour: the status source without sacct
MinJobAge=3600
${node} NodeAddr=127.0.0.1 State=UNKNOWN
# a test cluster on a small machine: up to two jobs may share a core (a grouped job holding every core
# does not have to wait for a one-core job to finish)
PartitionName=debug Nodes=${host} Default=YES MaxTime=INFINITE State=UP OverSubscribe=FORCE:2
CONF

  if ! pgrep -x slurmctld >/dev/null; then
    # -c: start from an empty job table (state of an earlier test run is of no use)
    slurmctld -c
    for _ in $(seq 1 50); do [ -s /run/slurmctld.pid ] && break; sleep 0.1; done
    echo "slurmctld $(cat /run/slurmctld.pid)" >>"$STARTED"
  fi
  if ! pgrep -x slurmd >/dev/null; then
    slurmd
    for _ in $(seq 1 50); do [ -s /run/slurmd.pid ] && break; sleep 0.1; done
    echo "slurmd $(cat /run/slurmd.pid)" >>"$STARTED"
  fi
  for _ in $(seq 1 60); do
    if is_up; then
      echo "slurm up ($(partition_state)): ${node}"
      return 0
    fi
    sleep 0.5
  done
  echo "slurm did not come up" >&2
  sinfo >&2 || true
  tail -20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
  return 1
}

case "${1:-start}" in
  start) start ;;
  stop) stop ;;
  *) echo "usage: $0 [start|stop]" >&2; exit 64 ;;
esac

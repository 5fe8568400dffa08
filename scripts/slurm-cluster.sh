#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for testing `monolayer figures --slurm` against the
# real thing (not a mock): Debian's slurm-wlm and munge, no systemd, no cgroups.
#
#   sudo bash scripts/slurm-cluster.sh start    # install if needed, configure, start, wait for idle
#   sudo bash scripts/slurm-cluster.sh status
#   sudo bash scripts/slurm-cluster.sh stop     # the daemons this script started, by their pid files
#
# It writes /etc/slurm/slurm.conf only when there is none or when this script wrote the one there
# (its first line says so): a cluster configured by someone else is never touched.
set -euo pipefail

MARK="# written by monolayer scripts/slurm-cluster.sh"
CONF=/etc/slurm/slurm.conf
RUN=/run/monolayer-slurm
STATE=/var/lib/slurm/monolayer

die() { echo "slurm-cluster: $*" >&2; exit 1; }

need_root() { [ "$(id -u)" = 0 ] || die "must run as root (it installs packages and starts daemons)"; }

install() {
  if command -v sbatch >/dev/null && [ -x /usr/sbin/slurmctld ] && [ -x /usr/sbin/slurmd ] && [ -x /usr/sbin/munged ]; then
    return
  fi
  echo "slurm-cluster: installing slurm-wlm and munge (apt-get)"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
}

configure() {
  if [ -f "$CONF" ] && [ "$(head -n1 "$CONF")" != "$MARK" ]; then
    echo "slurm-cluster: $CONF exists and was not written by this script: using it as it is"
    return
  fi
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc)
  # Slurm drains a node that has less memory than it says; leave room.
  mem=$(awk '/MemTotal/ { printf "%d", $2 / 1024 * 0.9 }' /proc/meminfo)
  mkdir -p /etc/slurm "$STATE/ctld" "$STATE/d" "$RUN"
  cat >"$CONF" <<EOF
$MARK
ClusterName=monolayer
# 127.0.0.1: a fresh container's hostname need not resolve.
SlurmctldHost=$host(127.0.0.1)
AuthType=auth/munge
CryptoType=crypto/munge
SlurmUser=root
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
ReturnToService=2
MaxArraySize=10001
SlurmctldTimeout=30
SlurmdTimeout=30
MinJobAge=30
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

# A daemon removes its pid file as it exits: read it once, quietly.
alive() { local pid; pid=$(cat "$1" 2>/dev/null) && kill -0 "$pid" 2>/dev/null; }

start() {
  need_root
  install
  configure
  mkdir -p "$RUN"
  if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    [ -f /etc/munge/munge.key ] || /usr/sbin/mungekey --create >/dev/null
    mkdir -p /run/munge && chown munge:munge /run/munge
    # munged writes its pid file as the munge user: it lives in munge's own /run/munge.
    runuser -u munge -- /usr/sbin/munged 2>/dev/null || /usr/sbin/munged --force
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
    munge -n | unmunge >/dev/null || die "munge does not answer"
  fi
  alive "$RUN/slurmctld.pid" || /usr/sbin/slurmctld
  alive "$RUN/slurmd.pid" || /usr/sbin/slurmd
  for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
      echo "slurm-cluster: up: $(sinfo -h -o '%P %D %T %c CPUs')"
      return
    fi
    sleep 1
  done
  sinfo >&2 || true
  die "the node did not come up idle within 60 s (logs in $STATE)"
}

stop() {
  need_root
  for pid in "$RUN/slurmd.pid" "$RUN/slurmctld.pid" /run/munge/munged.pid; do
    if alive "$pid"; then
      kill "$(cat "$pid" 2>/dev/null)" 2>/dev/null || true
      for _ in $(seq 50); do alive "$pid" || break; sleep 0.1; done
    fi
  done
  echo "slurm-cluster: stopped"
}

status() {
  for pid in /run/munge/munged.pid "$RUN/slurmctld.pid" "$RUN/slurmd.pid"; do
    if alive "$pid"; then echo "$(basename "$pid" .pid): running ($(cat "$pid" 2>/dev/null))"; else echo "$(basename "$pid" .pid): not running"; fi
  done
  sinfo 2>/dev/null || true
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  status) status ;;
  *) die "usage: $0 start|stop|status" ;;
esac

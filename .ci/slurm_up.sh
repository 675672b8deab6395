#!/usr/bin/env bash
# A real single-node Slurm for CI (Debian's slurmctld, slurmd and munge), so run_seeds.py --launcher slurm is tested
# against Slurm itself, not a mock. Needs root and apt (a Debian container).
#
#     bash .ci/slurm_up.sh up     # install, write /etc/slurm/slurm.conf, start munged + slurmctld + slurmd, wait idle
#     bash .ci/slurm_up.sh down   # stop the three daemons
#
# The node is this machine (its hostname, all its CPUs, its memory), one partition `debug`. We are in a container:
# no systemd and no cgroups, so processes are tracked by parent pid (proctrack/linuxproc) and tasks are not bound
# (task/none). No accounting database: sacct has nothing to say, so run_seeds.py reads a timed-out job's stderr.
# If a daemon does not come up, its log is printed and the script fails. `up` first stops daemons an earlier `up` left.
# SLURMD_NICE=10: slurmd (and so every job) runs at that niceness, to share a machine politely.
set -euo pipefail

LOG_DIR=/var/log/slurm
CONF=/etc/slurm/slurm.conf
WAIT_S=${SLURM_UP_WAIT_S:-60}

fail() {
  echo "error: $*" >&2
  for f in /var/log/munge/munged.log "$LOG_DIR/slurmctld.log" "$LOG_DIR/slurmd.log"; do
    [[ -f $f ]] && { echo "---- tail of $f" >&2; tail -n 40 "$f" >&2; }
  done
  exit 1
}

# wait_for SECONDS DESCRIPTION COMMAND...: poll COMMAND once a second until it succeeds
wait_for() {
  local seconds=$1 what=$2
  shift 2
  for ((i = 0; i < seconds; i++)); do
    if "$@" >/dev/null 2>&1; then return 0; fi
    sleep 1
  done
  fail "$what did not happen within ${seconds}s"
}

node_idle() { [[ "$(sinfo -h -N -o %t 2>/dev/null)" == idle* ]]; }

up() {
  down
  if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      slurmctld slurmd slurm-client munge >/dev/null
  fi
  local host cpus mem_mb
  host=$(hostname -s)
  cpus=$(nproc)
  mem_mb=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512))
  mkdir -p /etc/slurm "$LOG_DIR" /var/spool/slurmctld /var/spool/slurmd /run/slurm
  : >"$LOG_DIR/slurmctld.log" && : >"$LOG_DIR/slurmd.log" # so a failure shows this start's lines only
  [[ -f /var/log/munge/munged.log ]] && : >/var/log/munge/munged.log
  cat >"$CONF" <<EOF
# written by .ci/slurm_up.sh: one node (this machine), one partition, no accounting, no cgroups
ClusterName=ci
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
ReturnToService=2
# seconds between SIGTERM and SIGKILL when a job is cancelled or hits its time limit (default 30)
KillWait=10
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurm/slurmctld.pid
SlurmdPidFile=/run/slurm/slurmd.pid
SlurmctldLogFile=$LOG_DIR/slurmctld.log
SlurmdLogFile=$LOG_DIR/slurmd.log
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  # munge: the package made a key; the daemon runs as the munge user
  mkdir -p /run/munge && chown munge:munge /run/munge && chmod 755 /run/munge
  if ! pgrep -u munge -x munged >/dev/null; then
    runuser -u munge -- /usr/sbin/munged || fail "munged did not start"
  fi
  wait_for 10 "munge credential round trip" bash -c 'munge -n | unmunge'
  # -c: a clean state (no jobs left from an earlier start)
  slurmctld -c || fail "slurmctld did not start"
  wait_for "$WAIT_S" "slurmctld answering (scontrol ping)" bash -c 'scontrol ping | grep -q UP'
  nice -n "${SLURMD_NICE:-0}" slurmd || fail "slurmd did not start"
  wait_for "$WAIT_S" "node $host idle in sinfo" node_idle
  sinfo
}

stop_pidfile() {
  local pidfile=$1
  [[ -f $pidfile ]] || return 0
  local pid
  pid=$(cat "$pidfile")
  kill "$pid" 2>/dev/null || true
  for ((i = 0; i < 20; i++)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.5
  done
  echo "warning: pid $pid from $pidfile still running after 10s" >&2
}

down() {
  stop_pidfile /run/slurm/slurmd.pid
  stop_pidfile /run/slurm/slurmctld.pid
  stop_pidfile /run/munge/munged.pid
}

case "${1:-}" in
up) up ;;
down) down ;;
*)
  echo "usage: $0 up|down" >&2
  exit 2
  ;;
esac

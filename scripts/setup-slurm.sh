#!/usr/bin/env bash
# A single-node SLURM on this machine, for the cluster tests and for trying `tandem reproduce
# --slurm` without a cluster. Everything it writes lives under the git-ignored `.slurm/` of the
# repository: the munge key and socket, slurm.conf, the daemons' state, logs and process ids.
#
#   scripts/setup-slurm.sh          install (Debian's slurm-wlm and munge) if needed, then start
#                                   munged, slurmctld and slurmd; already running: nothing to do
#   scripts/setup-slurm.sh stop     stop the daemons by their recorded process ids
#
# Then `export SLURM_CONF=$PWD/.slurm/etc/slurm.conf` (or `. .slurm/env`) points sbatch, squeue
# and scontrol at it. It runs as root (apt-get, and daemons that start jobs as their users).
#
# Exit status: 0 when the cluster is up (or stopped), 3 when the packages cannot be installed or
# it does not run as root (said loudly on stderr; `.ci/run` then skips the cluster tests), 1 on
# any other failure.
set -euo pipefail
cd "$(dirname "$0")/.."
DIR="$PWD/.slurm"
RUN="$DIR/run"
LOG="$DIR/log"
CONF="$DIR/etc/slurm.conf"

pid_alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

stop() {
    local name pid
    for name in slurmd slurmctld munged; do
        if pid_alive "$RUN/$name.pid"; then
            pid="$(cat "$RUN/$name.pid")"
            kill "$pid"
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            if kill -0 "$pid" 2>/dev/null; then kill -9 "$pid"; fi
            echo "setup-slurm: stopped $name ($pid)"
        fi
        rm -f "$RUN/$name.pid"
    done
}

if [ "${1:-}" = "stop" ]; then
    stop
    exit 0
elif [ -n "${1:-}" ]; then
    echo "usage: $0 [stop]" >&2
    exit 1
fi

if [ "$(id -u)" -ne 0 ]; then
    echo "setup-slurm: NOT SET UP: it runs as root (it installs packages and starts SLURM's daemons)" >&2
    exit 3
fi

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v munged >/dev/null || ! command -v sbatch >/dev/null; then
    mkdir -p "$DIR"
    apt_log="$DIR/apt.log"
    if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y \
        --no-install-recommends slurm-wlm munge; } >"$apt_log" 2>&1; then
        {
            echo "================================================================"
            echo "setup-slurm: CANNOT INSTALL Debian's slurm-wlm and munge; the single-node"
            echo "SLURM is NOT set up. apt-get said (last lines of $apt_log):"
            tail -n 5 "$apt_log"
            echo "================================================================"
        } >&2
        exit 3
    fi
fi

if pid_alive "$RUN/munged.pid" && pid_alive "$RUN/slurmctld.pid" && pid_alive "$RUN/slurmd.pid"; then
    echo "setup-slurm: already running (SLURM_CONF=$CONF)"
    exit 0
fi
stop >/dev/null

mkdir -p "$DIR/etc" "$DIR/munge" "$DIR/state" "$DIR/spool" "$RUN" "$LOG"
chmod 0700 "$DIR/munge" "$RUN"
if [ ! -s "$DIR/munge/munge.key" ]; then
    dd if=/dev/urandom of="$DIR/munge/munge.key" bs=1024 count=1 status=none
fi
chmod 0400 "$DIR/munge/munge.key"
munged --force --key-file="$DIR/munge/munge.key" --socket="$RUN/munge.socket" \
    --pid-file="$RUN/munged.pid" --log-file="$LOG/munged.log" --seed-file="$DIR/munge/munge.seed"

host="$(hostname -s)"
cpus="$(nproc)"
mem_mib="$(awk '/MemTotal/ { print int($2 / 1024) }' /proc/meminfo)"
cat >"$CONF" <<EOF
# Written by scripts/setup-slurm.sh: one node, this machine.
ClusterName=tandem
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$RUN/munge.socket
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobRequeue=1
ReturnToService=2
KillWait=10
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$LOG/slurmctld.log
SlurmdLogFile=$LOG/slurmd.log
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mib State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
echo "export SLURM_CONF=$CONF" >"$DIR/env"
export SLURM_CONF="$CONF"

slurmctld -i
slurmd
for _ in $(seq 100); do
    if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        echo "setup-slurm: up, one node of $cpus CPUs (SLURM_CONF=$CONF)"
        exit 0
    fi
    sleep 0.2
done
echo "setup-slurm: the node did not come up; logs in $LOG:" >&2
tail -n 20 "$LOG/slurmctld.log" "$LOG/slurmd.log" >&2 || true
exit 1

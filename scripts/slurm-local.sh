#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the Slurm test of `unispine reproduce`
# (tests/reproduce/slurm.rs) and for trying --emit-slurm locally. Debian, root, no systemd needed.
#
#   bash scripts/slurm-local.sh start    # install (apt) if needed, configure, start munge + Slurm
#   bash scripts/slurm-local.sh stop     # stop what `start` started (by the pids it recorded)
#   bash scripts/slurm-local.sh status
#
# Configuration for a one-node cluster in a sandbox: root as SlurmUser, munge auth, no cgroup
# plugins (proctrack/linuxproc, task/none), no accounting, the node and controller on 127.0.0.1
# (no DNS), and DependencyParameters=kill_invalid_depend so that a job that depends on a failed
# array (afterok) is cancelled instead of pending forever.
set -euo pipefail

STATE=/run/unispine-slurm
CONF=/etc/slurm/slurm.conf

install() {
    if command -v slurmctld >/dev/null && command -v slurmd >/dev/null \
        && command -v sbatch >/dev/null && command -v munged >/dev/null; then
        return
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
}

configure() {
    local host cpus mem
    host=$(hostname -s)
    cpus=$(nproc)
    mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 8 / 10 ))
    mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm "$STATE"
    cat > "$CONF" <<CONF
ClusterName=unispine
SlurmctldHost=${host}(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MailProg=/bin/true
DependencyParameters=kill_invalid_depend
ReturnToService=2
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
NodeName=${host} NodeAddr=127.0.0.1 CPUs=${cpus} RealMemory=${mem} State=UNKNOWN
PartitionName=local Nodes=${host} Default=YES MaxTime=INFINITE State=UP
CONF
}

start() {
    install
    configure
    if [ ! -f /etc/munge/munge.key ]; then
        mungekey --create >/dev/null 2>&1 || /usr/sbin/mungekey --create
        chown munge:munge /etc/munge/munge.key
        chmod 0400 /etc/munge/munge.key
    fi
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    chmod 0755 /run/munge
    if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
        runuser -u munge -- /usr/sbin/munged --pid-file=/run/munge/munged.pid
        for _ in $(seq 50); do
            munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break
            sleep 0.1
        done
        cp /run/munge/munged.pid "$STATE/munged.pid" 2>/dev/null || true
    fi
    slurmctld
    sleep 1
    slurmd
    for _ in $(seq 100); do
        state=$(sinfo -h -N -o %T 2>/dev/null | head -1 || true)
        if [ "$state" = "idle" ]; then
            echo "slurm: node $(hostname -s) idle"
            return 0
        fi
        sleep 0.2
    done
    echo "slurm: the node did not become idle (state: ${state:-none}); see /var/log/slurm/" >&2
    return 1
}

stop_pid() {
    local f=$1
    [ -f "$f" ] || return 0
    local pid
    pid=$(cat "$f")
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
        kill "$pid" 2>/dev/null || true
        for _ in $(seq 50); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
    fi
    rm -f "$f"
}

stop() {
    scontrol shutdown >/dev/null 2>&1 || true
    stop_pid "$STATE/slurmd.pid"
    stop_pid "$STATE/slurmctld.pid"
    stop_pid "$STATE/munged.pid"
    echo "slurm: stopped"
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    status) sinfo -h -N -o "%N %T" ;;
    *) echo "usage: $0 start|stop|status" >&2; exit 2 ;;
esac

#!/usr/bin/env bash
# A single-node SLURM on this machine, to run `tonguevis batch --slurm` and its tests against.
#
#   scripts/slurm_local.sh start    # install slurm-wlm and munge when missing, configure, start the daemons
#   scripts/slurm_local.sh stop     # stop the daemons this script started (by their process ids)
#   scripts/slurm_local.sh status   # the daemons' ids, sinfo
#
# No systemd: munged, slurmctld and slurmd run in the foreground (-D / -F) as background processes;
# proctrack/linuxproc and task/none (no cgroups), loopback only (the node is this host by its name, the
# controller and the node are reached on 127.0.0.1 through NodeAddr). Needs root (as CI and the
# developers' machines are). The configuration is written to /etc/slurm/slurm.conf with a marker line;
# a slurm.conf without it (a real cluster's) is never touched. State and logs: $SLURM_LOCAL_DIR
# (default /var/tmp/tonguevis-slurm): the daemons' pids, slurmctld.log, slurmd.log, munged.log.
set -euo pipefail

STATE="${SLURM_LOCAL_DIR:-/var/tmp/tonguevis-slurm}"
CONF=/etc/slurm/slurm.conf
MARKER="# written by tonguevis scripts/slurm_local.sh"
PARTITION=debug

say() { echo "slurm_local: $*" >&2; }
die() { say "$*"; exit 1; }

alive() {  # alive NAME: the daemon this script started is running (its pid, not a process that took it over since)
    local pidfile="$STATE/$1.pid" pid
    [[ -f "$pidfile" ]] || return 1
    pid="$(cat "$pidfile")"
    [[ "$(cat "/proc/$pid/comm" 2>/dev/null)" == "$1" ]]
}

install_packages() {
    if command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v munged >/dev/null \
            && command -v sbatch >/dev/null; then
        return
    fi
    command -v apt-get >/dev/null || die "slurmctld, slurmd or munged is missing and there is no apt-get to install them"
    say "installing slurm-wlm and munge (Debian packages)"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
}

start_munge() {
    if alive munged && munge -n | unmunge >/dev/null 2>&1; then
        return
    fi
    install -d -o munge -g munge -m 0700 /etc/munge /var/log/munge
    install -d -o munge -g munge -m 0711 /var/lib/munge
    install -d -o munge -g munge -m 0755 /run/munge
    if [[ ! -s /etc/munge/munge.key ]]; then
        dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    fi
    chown munge:munge /etc/munge/munge.key
    chmod 0400 /etc/munge/munge.key
    # -F: in the foreground (here: a background process of ours); --force: a stale socket of a dead munged;
    # setpriv executes it as the munge user in place, so $! is munged itself
    setpriv --reuid=munge --regid=munge --init-groups munged -F --force >"$STATE/munged.log" 2>&1 &
    echo $! >"$STATE/munged.pid"
    for _ in $(seq 50); do
        munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && return
        sleep 0.1
    done
    die "munged did not start (see $STATE/munged.log)"
}

write_config() {
    if [[ -f "$CONF" ]] && ! grep -qF "$MARKER" "$CONF"; then
        die "$CONF exists and was not written by this script: leaving it alone (a real cluster's?)"
    fi
    local host cpus memory
    host="$(hostname -s)"
    cpus="$(nproc)"
    # RealMemory a little under the machine's (MB): slurmd drains a node that reports less than configured
    memory=$(( $(awk '/^MemTotal:/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 ))
    install -d -m 0755 /etc/slurm /var/spool/slurmctld /var/spool/slurmd
    cat >"$CONF" <<EOF
$MARKER
ClusterName=local
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=$STATE/slurmctld.daemon.pid
SlurmdPidFile=$STATE/slurmd.daemon.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
# a cancelled job's processes get SIGTERM, then SIGKILL after KillWait seconds
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=$PARTITION Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

wait_for_node() {
    local state=""
    for _ in $(seq 100); do
        state="$(sinfo --noheader --partition="$PARTITION" --format=%T 2>/dev/null | head -n1 || true)"
        case "$state" in
            idle*|mixed*|allocated*) return ;;
        esac
        sleep 0.2
    done
    die "the node did not come up (state '${state:-none}'; see $STATE/slurmctld.log and $STATE/slurmd.log)"
}

start() {
    [[ "$(id -u)" == 0 ]] || die "needs root (it installs packages and runs the daemons)"
    install -d -m 0755 "$STATE"
    install_packages
    start_munge
    if alive slurmctld && alive slurmd; then
        wait_for_node
        say "already running: $(slurmctld -V)"
        return
    fi
    write_config
    if ! alive slurmctld; then
        slurmctld -D -i >>"$STATE/slurmctld.out" 2>&1 &
        echo $! >"$STATE/slurmctld.pid"
    fi
    for _ in $(seq 50); do scontrol ping >/dev/null 2>&1 && break; sleep 0.1; done
    if ! alive slurmd; then
        slurmd -D >>"$STATE/slurmd.out" 2>&1 &
        echo $! >"$STATE/slurmd.pid"
    fi
    wait_for_node
    # a node drained by an earlier unclean stop comes back
    scontrol update nodename="$(hostname -s)" state=resume >/dev/null 2>&1 || true
    say "running: $(slurmctld -V), partition $PARTITION, node $(hostname -s) ($(nproc) CPUs); logs in $STATE"
}

stop() {
    local name pid
    # the jobs first (their processes are children of slurmd's job steps)
    if alive slurmctld; then
        scancel --full --partition="$PARTITION" >/dev/null 2>&1 || true
    fi
    for name in slurmd slurmctld munged; do
        if alive "$name"; then
            pid="$(cat "$STATE/$name.pid")"
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            if kill -0 "$pid" 2>/dev/null; then
                say "$name ($pid) did not stop on SIGTERM: SIGKILL"
                kill -9 "$pid" 2>/dev/null || true
            fi
            say "stopped $name ($pid)"
        fi
        rm -f "$STATE/$name.pid"
    done
}

status() {
    local name
    for name in munged slurmctld slurmd; do
        if alive "$name"; then echo "$name: running ($(cat "$STATE/$name.pid"))"; else echo "$name: not running"; fi
    done
    if alive slurmctld; then sinfo; fi
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    status) status ;;
    *) echo "usage: $0 start|stop|status" >&2; exit 2 ;;
esac

#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, with job accounting, for tests/test_slurm.py and for
# trying profiles/slurm by hand. Everything (configs, state, logs, sockets, the accounting
# database) lives in one folder, DIR (default /tmp/dpht-slurm); nothing in /etc is changed.
#
#   tests/cluster/slurm.sh start [DIR]   install Debian's SLURM, munge and MariaDB if missing, write
#                                        slurm.conf for this host, start munged, mariadbd,
#                                        slurmdbd, slurmctld and slurmd, wait until the node is idle
#   tests/cluster/slurm.sh stop [DIR]    cancel the cluster's jobs and stop its daemons
#   tests/cluster/slurm.sh env [DIR]     print the line that points SLURM's commands at it:
#                                        eval "$(tests/cluster/slurm.sh env)"; sinfo
#
# Accounting: snakemake-executor-plugin-slurm asks `sacct` for job states (its default wherever
# sacct is installed) and checks accounts with `sacctmgr`; both need slurmdbd, which stores in a
# MySQL/MariaDB database. MPI: MpiDefault=pmix, so `srun -n N liggghts` starts Debian's OpenMPI
# ranks through PMIx (both are built on Debian's libpmix2). The node has this machine's CPUs and
# memory (`slurmd -C`). Ports (SLURM_TEST_PORT_BASE, default 16817): slurmctld +0, slurmd +1,
# slurmdbd +2, MariaDB +3, on 127.0.0.1 only. Needs root (the daemons run as root).
set -euo pipefail

ACTION=${1:-}
DIR=$(realpath -m "${2:-${DPHT_SLURM_DIR:-/tmp/dpht-slurm}}")
PORT=${SLURM_TEST_PORT_BASE:-16817}
CLUSTER=dpht
ACCOUNT=dpht
PARTITION=debug
# libpmix-dev: slurm's mpi/pmix plugin dlopen()s libpmix.so, which only the -dev package provides.
PACKAGES="slurmctld slurmd slurm-client slurmdbd munge mariadb-server libpmix-dev"
DB_PASSWORD=dpht-test  # the database listens on 127.0.0.1 only and lives as long as the cluster
DAEMONS="slurmd slurmctld slurmdbd mariadbd munged"  # stop order

die() { echo "slurm.sh: $*" >&2; exit 1; }
log() { echo "slurm.sh: $*" >&2; }

wait_for() {  # wait_for SECONDS WHAT COMMAND...
    local deadline=$((SECONDS + $1)) what=$2
    shift 2
    while [ "$SECONDS" -lt "$deadline" ]; do
        "$@" >/dev/null 2>&1 && return 0
        sleep 0.2
    done
    die "$what did not come up in time; logs in $DIR/log"
}

install_packages() {
    local missing=
    for p in $PACKAGES; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
    [ -z "$missing" ] && return 0
    [ "$(id -u)" = 0 ] || die "installing$missing needs root"
    log "apt-get install$missing"
    apt-get update -q >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $missing >/dev/null
}

start_daemon() {  # start_daemon NAME COMMAND...: run in the foreground mode of the daemon, detached
    local name=$1
    shift
    setsid "$@" >"$DIR/log/$name.out" 2>&1 </dev/null &
    echo $! >"$DIR/run/$name.pid"
}

write_configs() {
    local host cpus mem
    host=$(hostname -s)
    cpus=${SLURM_TEST_CPUS:-$(slurmd -C | sed -n 's/.* CPUs=\([0-9]*\).*/\1/p')}
    mem=$(slurmd -C | sed -n 's/.* RealMemory=\([0-9]*\).*/\1/p')
    cat >"$DIR/etc/slurm.conf" <<EOF
# One-node test cluster written by tests/cluster/slurm.sh
ClusterName=$CLUSTER
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$PORT
SlurmdPort=$((PORT + 1))
AuthType=auth/munge
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/run/slurmctld.daemon.pid
SlurmdPidFile=$DIR/run/slurmd.daemon.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
MailProg=/bin/true
# Configless: slurmd fetches this file from slurmctld and caches it where commands inside jobs find
# it (/run/slurm/conf); snakemake-executor-plugin-slurm's job step drops SLURM_CONF from the
# environment of the srun it starts, as a real cluster's nodes would not need it.
SlurmctldParameters=enable_configless
# No cgroup set-up needed: processes are tracked through /proc.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=pmix
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
ReturnToService=2
MinJobAge=300
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=$((PORT + 2))
AccountingStoreFlags=job_comment
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=task=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
    cat >"$DIR/etc/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdHost=localhost
DbdAddr=127.0.0.1
DbdPort=$((PORT + 2))
SlurmUser=root
LogFile=$DIR/log/slurmdbd.log
PidFile=$DIR/run/slurmdbd.daemon.pid
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$((PORT + 3))
StorageUser=slurm
StoragePass=$DB_PASSWORD
StorageLoc=slurm_acct_db
EOF
    chmod 600 "$DIR/etc/slurmdbd.conf"
}

node_idle() { [ "$(timeout 10 sinfo -h -N -o %t 2>/dev/null)" = idle ]; }

start() {
    [ "$(id -u)" = 0 ] || die "the test cluster's daemons run as root"
    install_packages
    if [ -d "$DIR" ] && [ -n "$(ls -A "$DIR")" ] && [ ! -f "$DIR/etc/slurm.conf" ]; then
        die "$DIR is not empty and holds no test cluster; give an empty or new folder"
    fi
    stop_daemons
    for port in $PORT $((PORT + 1)) $((PORT + 2)) $((PORT + 3)); do
        if ss -Hltn "sport = :$port" 2>/dev/null | grep -q .; then
            die "port $port is in use (another test cluster? stop it with '$0 stop ITS_DIR', or set SLURM_TEST_PORT_BASE)"
        fi
    done
    rm -rf "$DIR"
    mkdir -p "$DIR"/{etc,run,log,state,spool,db}
    write_configs
    export SLURM_CONF="$DIR/etc/slurm.conf"

    # munge on its default socket, as installed by Debian: a configless slurmd needs it before it
    # has read any config. A munged already running there (the system's) is used as it is.
    if ! munge --string ok >/dev/null 2>&1; then
        [ -f /etc/munge/munge.key ] || mungekey --create
        mkdir -p -m 755 /run/munge
        start_daemon munged munged --foreground --force --pid-file "$DIR/run/munged.daemon.pid" \
            --log-file "$DIR/log/munged.log" --seed-file "$DIR/run/munged.seed"
        wait_for 10 munged munge --string ok
    fi

    mariadb-install-db --no-defaults --datadir="$DIR/db" --user=root --skip-test-db \
        --auth-root-authentication-method=socket >"$DIR/log/mariadb-install.log" 2>&1 \
        || die "mariadb-install-db failed; see $DIR/log/mariadb-install.log"
    start_daemon mariadbd mariadbd --no-defaults --datadir="$DIR/db" --user=root \
        --socket="$DIR/run/mariadb.socket" --port=$((PORT + 3)) --bind-address=127.0.0.1 \
        --skip-name-resolve --pid-file="$DIR/run/mariadbd.daemon.pid" --log-error="$DIR/log/mariadbd.log"
    wait_for 30 mariadbd mariadb --no-defaults --socket="$DIR/run/mariadb.socket" -u root -e "SELECT 1"
    mariadb --no-defaults --socket="$DIR/run/mariadb.socket" -u root -e \
        "CREATE USER 'slurm'@'127.0.0.1' IDENTIFIED BY '$DB_PASSWORD';
         GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';"

    start_daemon slurmdbd slurmdbd -D
    wait_for 30 slurmdbd timeout 10 sacctmgr -n list cluster
    sacctmgr -i -Q add cluster "$CLUSTER" >/dev/null
    sacctmgr -i -Q add account "$ACCOUNT" Description="dpht test jobs" Organization=dpht >/dev/null
    sacctmgr -i -Q add user "$(id -un)" Account="$ACCOUNT" DefaultAccount="$ACCOUNT" >/dev/null

    start_daemon slurmctld slurmctld -D -i
    wait_for 30 slurmctld timeout 10 scontrol ping
    start_daemon slurmd slurmd -D -N "$(hostname -s)" --conf-server "127.0.0.1:$PORT"
    wait_for 60 "the node (idle in sinfo)" node_idle
    log "cluster '$CLUSTER' up: $(sinfo -h -N -o '%N %c CPUs %m MB %t'); account $ACCOUNT, partition $PARTITION"
    echo "export SLURM_CONF=$SLURM_CONF"
}

stop_daemons() {
    [ -d "$DIR/run" ] || return 0
    if [ -f "$DIR/etc/slurm.conf" ] && [ -f "$DIR/run/slurmctld.pid" ]; then
        SLURM_CONF="$DIR/etc/slurm.conf" timeout 10 scancel --full --quiet --user "$(id -un)" 2>/dev/null || true
    fi
    for name in $DAEMONS; do
        local pidfile="$DIR/run/$name.pid"
        [ -f "$pidfile" ] || continue
        local pid
        pid=$(cat "$pidfile")
        if kill -0 "$pid" 2>/dev/null; then
            kill -TERM "$pid"
            for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            kill -0 "$pid" 2>/dev/null && kill -KILL "$pid"
        fi
        rm -f "$pidfile"
    done
    return 0
}

case "$ACTION" in
    start) start ;;
    stop) stop_daemons; log "cluster in $DIR stopped" ;;
    env) echo "export SLURM_CONF=$DIR/etc/slurm.conf" ;;
    *) die "usage: $0 start|stop|env [DIR]" ;;
esac

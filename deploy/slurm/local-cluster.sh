#!/usr/bin/env bash
# A real single-node Slurm cluster on this machine, and the cluster path of
# surgbench run through it end to end:
#
#   1. installs Debian's slurm-wlm and munge if they are missing (root);
#   2. starts munged, slurmctld and slurmd as root with a minimal slurm.conf
#      (this host's short name, 127.0.0.1, proctrack/linuxproc, task/none,
#      select/cons_tres), every state, spool, socket and log file in a
#      temporary folder;
#   3. plans the quick standard comparison over 4 shards, submits
#      deploy/slurm/standard.sbatch as a 4-task array and
#      deploy/slurm/merge.sbatch with --dependency=afterok on it, and waits;
#   4. checks that the merged results.csv has the same rows and, in every
#      column but the timings, the same bits as a local `run --quick`
#      (deploy/compare-results.py);
#   5. stops the three daemons it started and removes the temporary folder.
#
# Usage: deploy/slurm/local-cluster.sh [--local RESULTS_CSV] [--keep]
#   --local FILE  compare with this results.csv of `surgbench run --quick`
#                 instead of running one (CI passes the one it has)
#   --keep        keep the temporary folder (logs, the sweep, the report)
# Environment: SURGBENCH (the binary; default target/release/surgbench),
# SLURM_PORTS (slurmctld and slurmd ports, default "6817 6818"),
# LOCAL_CLUSTER_TIMEOUT (seconds to wait for the jobs, default 1800).
#
# Runs as root on a machine with nothing else listening on those ports. A
# laptop works too (Debian or Ubuntu); it starts in about a minute.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${SURGBENCH:-$root/target/release/surgbench}
local_csv=""
keep=0
while [ $# -gt 0 ]; do
    case $1 in
        --local) local_csv=$(realpath "$2"); shift 2 ;;
        --keep) keep=1; shift ;;
        *) echo "usage: $0 [--local RESULTS_CSV] [--keep]" >&2; exit 2 ;;
    esac
done
if [ "$(id -u)" != 0 ]; then
    echo "error: $0 starts munged, slurmctld and slurmd as root; run it as root" >&2
    exit 2
fi
bin=$(realpath "$bin")
[ -x "$bin" ] || { echo "error: no surgbench binary at $bin (cargo build --release --bin surgbench)" >&2; exit 2; }
t0=$(date +%s)
say() { echo "[local-cluster $(( $(date +%s) - t0 )) s] $*"; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null || ! command -v sbatch >/dev/null; then
    say "installing slurm-wlm and munge"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge) >/dev/null
fi

work=$(mktemp -d /tmp/surgbench-slurm.XXXXXX)
chmod 755 "$work"
mkdir -p "$work"/{munge,state,spool,logs}
host=$(hostname -s)
read -r ctld_port slurmd_port <<<"${SLURM_PORTS:-6817 6818}"

stop() {
    # Only the daemons this script started, by the pids they wrote.
    for d in slurmd slurmctld munged; do
        if [ -s "$work/$d.pid" ]; then
            kill "$(cat "$work/$d.pid")" 2>/dev/null || true
        fi
    done
    sleep 1
    if [ "$keep" = 1 ]; then
        echo "kept $work"
    else
        rm -rf "$work"
    fi
}
trap stop EXIT

say "starting munged"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$work/munge/munge.key"
chmod 700 "$work/munge"
munged --force --key-file="$work/munge/munge.key" --socket="$work/munge/munge.socket" \
    --pid-file="$work/munged.pid" --log-file="$work/logs/munged.log" --seed-file="$work/munge/munged.seed"

# The node's CPUs and memory as slurmd sees them, under this host's name.
node=$(slurmd -C | head -1 | sed -e "s/^NodeName=[^ ]*/NodeName=$host NodeAddr=127.0.0.1/")
cat >"$work/slurm.conf" <<EOF
ClusterName=surgbench
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$work/munge/munge.socket
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/logs/slurmctld.log
SlurmdLogFile=$work/logs/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
MinJobAge=3600
$node State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$work/slurm.conf

say "starting slurmctld and slurmd on $host"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for _ in $(seq 120); do
    state=$(sinfo -h -n "$host" -o %t 2>/dev/null || true)
    case $state in idle*|mix*|alloc*) break ;; esac
    sleep 1
done
if ! sinfo -h -n "$host" -o %t | grep -qE '^(idle|mix|alloc)'; then
    echo "error: the node did not come up (state: ${state:-none}); logs in $work/logs" >&2
    tail -n 20 "$work"/logs/*.log >&2 || true
    keep=1
    exit 1
fi
say "cluster up: $(sinfo -h -o '%P %D nodes %c CPUs %t')"

# The three commands of the README's "Running on a cluster", with --quick.
sweep=$work/sweep
report=$work/report
cd "$root"
export SURGBENCH=$bin
"$bin" plan standard --quick --shards 4 --out "$sweep"
jid=$(sbatch --parsable --array=0-3 --chdir="$root" --output="$work/logs/shard-%a.out" \
    deploy/slurm/standard.sbatch "$sweep" standard --quick)
mid=$(sbatch --parsable --dependency=afterok:"$jid" --chdir="$root" --output="$work/logs/merge.out" \
    deploy/slurm/merge.sbatch "$report" "$sweep")
say "submitted array job $jid (4 tasks) and merge job $mid (afterok:$jid)"

limit=${LOCAL_CLUSTER_TIMEOUT:-1800}
while squeue -h -j "$jid,$mid" 2>/dev/null | grep -q .; do
    if [ $(( $(date +%s) - t0 )) -gt "$limit" ]; then
        echo "error: the jobs did not finish within $limit s" >&2
        squeue >&2 || true
        scancel "$jid" "$mid" || true
        keep=1
        exit 1
    fi
    sleep 5
done
merge_state=$(scontrol show job "$mid" 2>/dev/null | grep -o 'JobState=[A-Z_]*' || echo "JobState=unknown")
say "jobs done: merge $merge_state"
for f in "$work"/logs/shard-*.out "$work"/logs/merge.out; do
    echo "--- $(basename "$f")"
    tail -n 3 "$f"
done
if [ "$merge_state" != JobState=COMPLETED ] || [ ! -s "$report/results.csv" ]; then
    echo "error: the merge job did not write $report/results.csv; logs in $work/logs" >&2
    keep=1
    exit 1
fi

if [ -z "$local_csv" ]; then
    say "running the quick comparison locally to compare"
    # Outside the cluster: no array index in the environment.
    env -u SLURM_ARRAY_TASK_ID "$bin" run standard --quick --quiet --out "$work/local"
    local_csv=$work/local/results.csv
fi
python3 "$root/deploy/compare-results.py" "$local_csv" "$report/results.csv"
say "done"

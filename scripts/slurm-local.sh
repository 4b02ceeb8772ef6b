#!/usr/bin/env bash
# A sweep on a real Slurm, on this machine alone: installs Debian's slurm-wlm and munge if
# missing, writes a one-node configuration (in a scratch folder; /etc/slurm is left alone),
# starts munged (unless one runs), slurmctld and slurmd, submits a small sweep with
# `learner experiment comparison --slurm DIR --submit` (2 variants x 4 seeds x 5 iterations,
# 4 shards, one at a time), waits for its merge job and checks that the merged CSV equals the
# unsharded run's bit for bit bar the timing columns (t_*, cpu_*), and that the expert job's
# demonstrations are the unsharded run's. Then runs one shard task a second time (as a retry
# would), merges again and checks the same CSV, and checks that a merge without one shard
# names it. Stops the daemons it started at the end.
#
# Needs root (apt-get, the daemons) and a built learner (cargo build --release -p learner or
# the workspace's tests). Settings by environment:
#   LEARNER  the learner executable [target/release/learner]
#   WORK     scratch folder [a new /tmp/slurm-local.XXXXXX, kept for its logs]
#   SEEDS, ITERATIONS, SHARDS, PARALLEL  the sweep [4, 5, 4, 1]
#   TIMEOUT  seconds to wait for the merge job [1800]
# Prints the sweep's wall time (submit to merged) and exits non-zero on any difference.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
LEARNER=${LEARNER:-$ROOT/target/release/learner}
SEEDS=${SEEDS:-4}
ITERATIONS=${ITERATIONS:-5}
SHARDS=${SHARDS:-4}
PARALLEL=${PARALLEL:-1}
TIMEOUT=${TIMEOUT:-1800}
[ -x "$LEARNER" ] || { echo "no learner at $LEARNER (cargo build --release)" >&2; exit 2; }
[ "$(id -u)" = 0 ] || { echo "run as root (installs packages, starts daemons)" >&2; exit 2; }

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null \
    || ! command -v munge >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge
fi

WORK=${WORK:-$(mktemp -d /tmp/slurm-local.XXXXXX)}
mkdir -p "$WORK"/{state,spool,sweep}
NODE=$(hostname -s)
CPUS=$(nproc)
MEM=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)
export SLURM_CONF=$WORK/slurm.conf
cat >"$SLURM_CONF" <<EOF
# One node, this machine; no cgroups, no accounting.
ClusterName=local
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/slurmctld.log
SlurmdLogFile=$WORK/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
MpiDefault=none
MinJobAge=3600
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$CPUS RealMemory=$MEM State=UNKNOWN
PartitionName=local Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF

PIDS=()
stop() {
    for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
    for p in "${PIDS[@]}"; do wait "$p" 2>/dev/null || true; done
}
trap stop EXIT

# A munged that already runs (a credential encodes) is used as it is.
if ! munge -n </dev/null >/dev/null 2>&1; then
    [ -f /etc/munge/munge.key ] || mungekey --create
    mkdir -p /run/munge && chown munge:munge /run/munge
    runuser -u munge -- munged -F >"$WORK/munged.out" 2>&1 &
    PIDS+=($!)
fi
for _ in $(seq 50); do munge -n </dev/null >/dev/null 2>&1 && break; sleep 0.2; done
munge -n </dev/null | unmunge >/dev/null

slurmctld -D -f "$SLURM_CONF" >"$WORK/slurmctld.out" 2>&1 &
PIDS+=($!)
slurmd -D -N "$NODE" -f "$SLURM_CONF" >"$WORK/slurmd.out" 2>&1 &
PIDS+=($!)
for _ in $(seq 100); do
    sinfo -h -o %T 2>/dev/null | grep -qx idle && break
    sleep 0.3
done
sinfo -h -o '%P %T %c' | grep -q idle || { echo "slurm node not idle:" >&2; sinfo >&2; exit 1; }
echo "slurm up: $(sinfo -h -o '%P %D node(s) %c cpus %T')"

# Two variants: LQR+GAIfO and GAIfO (PPO) at the paper's budget.
CONFIG=$WORK/comparison.toml
echo 'algorithms = ["lqr-gaifo", "gaifo-ppo"]' >"$CONFIG"
SWEEP=(comparison --config "$CONFIG" --seeds "$SEEDS" --iterations "$ITERATIONS")

T0=$(date +%s.%N)
"$LEARNER" experiment "${SWEEP[@]}" --slurm "$WORK/sweep" --shards "$SHARDS" \
    --parallel "$PARALLEL" --partition local --time 01:00:00 --submit | tee "$WORK/submitted"
MERGE=$(awk '/^merge job/ {print $3}' "$WORK/submitted")
[ -n "$MERGE" ] || { echo "no merge job id printed" >&2; exit 1; }
state() { scontrol show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2; }
# Waits for job $1 to complete; fails on its failure or a dependency it can never meet.
wait_job() {
    local deadline=$(($(date +%s) + TIMEOUT)) s
    while :; do
        s=$(state "$1")
        case "$s" in
        COMPLETED) return 0 ;;
        FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY | "")
            echo "job $1: ${s:-gone}" >&2
            tail -n 20 "$WORK"/sweep/logs/*.out >&2 || true
            exit 1
            ;;
        esac
        if scontrol show job "$1" | grep -q 'Reason=DependencyNeverSatisfied'; then
            echo "job $1: a job it depends on failed" >&2
            tail -n 20 "$WORK"/sweep/logs/*.out >&2 || true
            exit 1
        fi
        [ "$(date +%s)" -lt "$deadline" ] || { echo "job $1: timed out after ${TIMEOUT}s" >&2; exit 1; }
        sleep 1
    done
}
wait_job "$MERGE"
T1=$(date +%s.%N)
WALL=$(awk -v a="$T0" -v b="$T1" 'BEGIN {printf "%.0f", b - a}')
echo "sweep under slurm: ${WALL} s from submit to merged ($SHARDS shards, $PARALLEL at once)"

# The unsharded run, here, for the reference.
T0=$(date +%s.%N)
"$LEARNER" experiment "${SWEEP[@]}" --threads 1 --out "$WORK/whole" 2>"$WORK/whole.log"
T1=$(date +%s.%N)
echo "unsharded run: $(awk -v a="$T0" -v b="$T1" 'BEGIN {printf "%.0f", b - a}') s"

# CSV rows without the timing columns (t_*, cpu_*).
untimed() {
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) keep[i] = ($i !~ /^(t_|cpu_)/) }
        { s = ""; for (i = 1; i <= NF; i++) if (keep[i]) s = s (s == "" ? "" : ",") $i; print s }' "$1"
}
FAIL=0
if cmp -s "$WORK/sweep/expert/demos.npz" "$WORK/whole/demos.npz"; then
    echo "ok: the expert job's demonstrations are the unsharded run's"
else
    echo "DIFFERENT: expert/demos.npz vs the unsharded run's demos.npz" >&2
    FAIL=1
fi
if diff <(untimed "$WORK/sweep/merged/comparison.csv") <(untimed "$WORK/whole/comparison.csv") \
    >"$WORK/csv.diff"; then
    echo "ok: merged comparison.csv equals the unsharded run's ($(($(wc -l <"$WORK/whole/comparison.csv") - 1)) rows, timing columns aside)"
else
    echo "DIFFERENT: merged vs unsharded comparison.csv (see $WORK/csv.diff)" >&2
    FAIL=1
fi

# Shard 2 again, as a retried task would run it, then the merge again: the same CSV.
cp "$WORK/sweep/merged/comparison.csv" "$WORK/merged-first.csv"
AGAIN=$(sbatch --parsable --array=2 "$WORK/sweep/shards.sbatch" | cut -d';' -f1)
MERGE2=$(sbatch --parsable --dependency=afterok:"$AGAIN" "$WORK/sweep/merge.sbatch" | cut -d';' -f1)
wait_job "$MERGE2"
if diff <(untimed "$WORK/merged-first.csv") <(untimed "$WORK/sweep/merged/comparison.csv") >/dev/null \
    && [ -z "$(find "$WORK/sweep" -maxdepth 1 -name '.shard_*')" ]; then
    echo "ok: shard 2 run twice (job $AGAIN), merged again (job $MERGE2): the same CSV, no temporaries"
else
    echo "DIFFERENT: the merge after shard 2 ran twice, or a temporary folder left" >&2
    FAIL=1
fi
# A merge without shard 3 names it and writes nothing.
S=$WORK/sweep
if "$LEARNER" experiment merge "$S/shard_1" "$S/shard_2" "$S/shard_4" --out "$WORK/no3" \
    2>"$WORK/no3.err"; then
    echo "WRONG: a merge without shard 3 succeeded" >&2
    FAIL=1
elif grep -q "missing shard(s) 3/$SHARDS" "$WORK/no3.err" && [ ! -e "$WORK/no3" ]; then
    echo "ok: a merge without shard 3 is refused: $(tail -n 1 "$WORK/no3.err")"
else
    echo "WRONG: a merge without shard 3 failed otherwise: $(cat "$WORK/no3.err")" >&2
    FAIL=1
fi
echo "logs and outputs: $WORK"
exit $FAIL

#!/usr/bin/env bash
# What Slurm costs per task, measured on a real single-node cluster in Linux namespaces (the
# test's, tests/farm/slurm_cluster.sh): an array of N tasks that do nothing but record when they
# start and end, then the dependent final job. Prints submission-to-first-start latency, the
# array's makespan, per-task wall, and the overhead per task (makespan x cores / N - work).
#   bench/farm_overhead.sh [N=40] [WORKDIR=/tmp/reshutter-farm-bench]
set -euo pipefail
n=${1:-40}
work=${2:-/tmp/reshutter-farm-bench}
here=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$work" && mkdir -p "$work/t"
measure() {
  set -euo pipefail
  cat > "$work/task.sh" <<S
#!/bin/sh
date +%s.%N > "$work/t/\$SLURM_ARRAY_TASK_ID.start"
date +%s.%N > "$work/t/\$SLURM_ARRAY_TASK_ID.end"
S
  t0=$(date +%s.%N)
  jid=$(sbatch --parsable --array=0-$((n - 1)) --output=/dev/null "$work/task.sh")
  t1=$(date +%s.%N)
  fid=$(sbatch --parsable --dependency=afterok:$jid --output=/dev/null --wrap "date +%s.%N > $work/final")
  for _ in $(seq 1200); do [ -z "$(squeue --noheader -o %i)" ] && break; sleep 0.1; done
  [ -z "$(squeue --noheader -o %i)" ] || { squeue; tail -5 "$work/cluster/log/slurmctld.log"; exit 1; }
  cpus=$(nproc)
  python3 - "$work" "$n" "$t0" "$t1" "$cpus" <<'PY'
import sys, glob
work, n, t0, t1, cpus = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
st = [float(open(f"{work}/t/{i}.start").read()) for i in range(n)]
en = [float(open(f"{work}/t/{i}.end").read()) for i in range(n)]
final = float(open(f"{work}/final").read())
span = max(en) - t0
work_s = sum(e - s for s, e in zip(st, en))
print(f"tasks {n} on {cpus} CPUs; sbatch itself {1e3*(t1-t0):.0f} ms")
print(f"submission -> first task start  {min(st)-t0:.2f} s")
print(f"submission -> last task end     {span:.2f} s  ({n/span:.1f} tasks/s)")
print(f"last task end -> final job start {final-max(en):.2f} s")
print(f"overhead per task (makespan x CPUs / tasks - work)  {span*cpus/n - work_s/n:.2f} CPU-s")
PY
}
export -f measure
export n work
"$here/tests/farm/slurm_cluster.sh" "$work/cluster" bash -c measure

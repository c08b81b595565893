#!/usr/bin/env bash
# Paired A/B timing of two reshutter binaries on a shared, noisy 2-core machine: each round runs A
# and B at the same time, one per core (taskset), single-threaded, swapping the cores every round,
# so both see the same neighbours' load; prints each round's user CPU seconds and the median of
# the per-round ratios B/A. A against itself gave ratios 0.91-1.03 (median 1.01) on the 2-vCPU
# EPYC VM: medians within ~3 % of 1 are noise. Not a test: run by hand.
#
# Usage: bench/paired_builds.sh [--rounds N] BIN_A BIN_B STORE [resample arguments...]
#   e.g. bench/paired_builds.sh --rounds 10 /tmp/base/reshutter build/reshutter moving.0001.mps \
#          --spp 16 --filter gaussian:2x2 --crop 480 1440 270 810
set -euo pipefail
rounds=8
if [[ ${1:-} == --rounds ]]; then rounds=$2; shift 2; fi
[[ $# -ge 3 ]] || { sed -n 2,10p "$0" >&2; exit 2; }
a=$1 b=$2 store=$3
shift 3
(( $(nproc) >= 2 )) || { echo "needs two cores" >&2; exit 2; }
work=$(mktemp -d /tmp/reshutter-paired.XXXXXX)
trap 'rm -rf "$work"' EXIT

for ((i = 1; i <= rounds; ++i)); do
  if (( i % 2 )); then ca=0 cb=1; else ca=1 cb=0; fi
  /usr/bin/time -o "$work/a.time" -f "%U" taskset -c $ca "$a" -q -j 1 resample "$store" "$@" -o "$work/a.exr" >/dev/null &
  /usr/bin/time -o "$work/b.time" -f "%U" taskset -c $cb "$b" -q -j 1 resample "$store" "$@" -o "$work/b.exr" >/dev/null &
  wait
  echo "$(cat "$work/a.time") $(cat "$work/b.time")"
done | python3 -c '
import statistics, sys
rows = [tuple(map(float, line.split())) for line in sys.stdin]
for a, b in rows: print(f"A {a:.2f}  B {b:.2f}  B/A {b / a:.3f}")
r = sorted(b / a for a, b in rows)
print(f"A median {statistics.median(a for a, _ in rows):.2f} s, B median {statistics.median(b for _, b in rows):.2f} s; "
      f"B/A median {statistics.median(r):.3f} (min {r[0]:.3f}, max {r[-1]:.3f}) over {len(r)} rounds")
'

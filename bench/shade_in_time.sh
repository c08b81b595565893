#!/usr/bin/env bash
# What shading in time costs against shading once (issue #29), the demo shaded into a store by
# bench/shade_bench at 5 times, tolerance 0.01; OpenImageIO's texture module is loaded before the
# timings (the pass alone).
#
#   bench/shade_in_time.sh [--rounds R] [--threads T] [--res W H] [--stride N] BUILD...
#       interleaved runs of each build, each in a fresh process: CPU seconds once and in time, and
#       the ratio per round (the host is noisy: read the median of the ratios); --stride: the
#       later times' coarse lattice (--shade-in-time-stride; builds from the thirty-first session on)
#   bench/shade_in_time.sh --cachegrind [--res W H] [--stride N] BUILD...
#       instructions of the whole process, one thread (repeatable); "none" is the process with
#       the module loaded and nothing shaded, to subtract
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/host.sh
rounds=5 threads=1 w=640 h=360 cachegrind=0
builds=() stride=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rounds) rounds="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --res) w="$2"; h="$3"; shift 2 ;;
    --cachegrind) cachegrind=1 ;;
    --stride) stride=(--stride "$2"); shift ;;
    -*) echo "usage: bench/shade_in_time.sh [--cachegrind] [--rounds R] [--threads T] [--res W H] [--stride N] BUILD..." >&2; exit 2 ;;
    *) builds+=("$1") ;;
  esac
  shift
done
[[ ${#builds[@]} -gt 0 ]] || { echo "bench/shade_in_time.sh: name at least one build directory" >&2; exit 2; }
bench() { "$1/bench/shade_bench" --shade-in-time --threads "$2" --only "$3" --res "$w" "$h" "${stride[@]}"; }
if [[ $cachegrind == 1 ]]; then
  command -v valgrind >/dev/null || { echo "bench/shade_in_time.sh: --cachegrind needs valgrind (apt-get install valgrind)" >&2; exit 1; }
  for b in "${builds[@]}"; do
    shim="$b/bench/libvalgrind_timer_shim.so"
    [[ -f "$shim" ]] || { echo "$shim missing: build the bench targets" >&2; exit 1; }
    for label in none once t0.01; do
      n=$(LD_PRELOAD="$shim" valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null \
            "$b/bench/shade_bench" --shade-in-time --threads 1 --only "$label" --res "$w" "$h" "${stride[@]}" 2>&1 | awk '/I +refs/ {gsub(",", "", $NF); print $NF}')
      echo "$b ${w}x$h $label $n instructions"
    done
  done
  exit 0
fi
for ((i = 0; i < rounds; ++i)); do
  for b in "${builds[@]}"; do
    once=$(bench "$b" "$threads" once | grep -oE '[0-9.]+ s cpu' | cut -d' ' -f1)
    timed=$(bench "$b" "$threads" t0.01 | grep -oE '[0-9.]+ s cpu' | cut -d' ' -f1)
    echo "$b $once $timed"
  done
done | python3 -c "
import collections, statistics, sys
runs = collections.defaultdict(list)
for line in sys.stdin:
    b, once, timed = line.split()
    runs[b].append((float(once), float(timed)))
for b, r in runs.items():
    ratios = [t / o for o, t in r]
    print(f'{b}: once', ' '.join(f'{o:.3f}' for o, _ in r), '| in time', ' '.join(f'{t:.3f}' for _, t in r),
          '| ratio', ' '.join(f'{x:.2f}' for x in ratios), f'median {statistics.median(ratios):.2f}')
"
echo "(${w}x$h, $threads thread(s); $(host_line))"

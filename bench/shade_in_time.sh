#!/usr/bin/env bash
# What shading in time costs against shading once (issue #29), the demo shaded into a store by
# bench/shade_bench at 5 times, tolerance 0.01; OpenImageIO's texture module is loaded before the
# timings (the pass alone).
#
#   bench/shade_in_time.sh [--rounds R] [--threads T] [--res W H] [--stride N] [--times N] [--tolerance T] BUILD...
#       interleaved runs of each build, each in a fresh process: CPU seconds once and in time, and
#       the ratio per round (the host is noisy: read the median of the ratios); --stride: the
#       later times' coarse lattice (--shade-in-time-stride; builds from the thirty-first session on)
#       and --times: the shading times (--shade-times, default 5; builds from the thirty-third on);
#       --tolerance 0.03, 0.01 (the default) or 0: the in-time pass's tolerance
#   bench/shade_in_time.sh --cachegrind [--res W H] [--stride N] [--times N] [--tolerance T] BUILD...
#       instructions of the whole process, one thread (repeatable); "none" is the process with
#       the module loaded and nothing shaded, to subtract
#   bench/shade_in_time.sh --breakdown [--res W H] [--stride N] [--times N] [--tolerance T] BUILD...
#       where the extra of shading in time goes (callgrind, one thread, the pass alone): the
#       later times, the store's writing, the rays through the moving scene (the accuracy study's
#       size is --res 256 144)
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/host.sh
rounds=5 threads=1 w=640 h=360 cachegrind=0 breakdown=0 timed_label=t0.01
builds=() passOptions=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rounds) rounds="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --res) w="$2"; h="$3"; shift 2 ;;
    --cachegrind) cachegrind=1 ;;
    --breakdown) breakdown=1 ;;
    --stride | --times) passOptions+=("$1" "$2"); shift ;;
    --tolerance) timed_label="t$2"; shift ;;
    -*) echo "usage: bench/shade_in_time.sh [--cachegrind | --breakdown] [--rounds R] [--threads T] [--res W H] [--stride N] [--times N] [--tolerance T] BUILD..." >&2; exit 2 ;;
    *) builds+=("$1") ;;
  esac
  shift
done
[[ ${#builds[@]} -gt 0 ]] || { echo "bench/shade_in_time.sh: name at least one build directory" >&2; exit 2; }
bench() { "$1/bench/shade_bench" --shade-in-time --threads "$2" --only "$3" --res "$w" "$h" "${passOptions[@]}"; }
if [[ $cachegrind == 1 ]]; then
  command -v valgrind >/dev/null || { echo "bench/shade_in_time.sh: --cachegrind needs valgrind (apt-get install valgrind)" >&2; exit 1; }
  for b in "${builds[@]}"; do
    shim="$b/bench/libvalgrind_timer_shim.so"
    [[ -f "$shim" ]] || { echo "$shim missing: build the bench targets" >&2; exit 1; }
    for label in none once $timed_label; do
      n=$(LD_PRELOAD="$shim" valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null \
            "$b/bench/shade_bench" --shade-in-time --threads 1 --only "$label" --res "$w" "$h" "${passOptions[@]}" 2>&1 | awk '/I +refs/ {gsub(",", "", $NF); print $NF}')
      echo "$b ${w}x$h $label $n instructions"
    done
  done
  exit 0
fi
if [[ $breakdown == 1 ]]; then
  command -v valgrind >/dev/null || { echo "bench/shade_in_time.sh: --breakdown needs valgrind (apt-get install valgrind)" >&2; exit 1; }
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  for b in "${builds[@]}"; do
    shim="$b/bench/libvalgrind_timer_shim.so"
    [[ -f "$shim" ]] || { echo "$shim missing: build the bench targets" >&2; exit 1; }
    for label in once $timed_label; do
      LD_PRELOAD="$shim" valgrind --tool=callgrind --callgrind-out-file="$tmp/$label.out" \
        "$b/bench/shade_bench" --shade-in-time --threads 1 --only "$label" --res "$w" "$h" "${passOptions[@]}" >/dev/null 2>&1 &
    done
    wait
    # Inclusive instructions of the first function whose name matches, per run.
    cost() { callgrind_annotate --inclusive=yes "$tmp/$1.out" 2>/dev/null | grep -E "^ *[0-9,]+ .*$2" | head -1 | awk '{gsub(",", "", $1); print $1 + 0}'; }
    once=$(cost once 'shade::shadeToStore') timed=$(cost $timed_label 'shade::shadeToStore')
    later=$(cost $timed_label 'pass::shadeInTime\(') moving=$(cost $timed_label 'ShadowScene::occludedByMoving')
    store=$(( $(cost $timed_label 'StoreWriter::close') - $(cost once 'StoreWriter::close') ))
    extra=$((timed - once))
    python3 - "$b" "$w" "$h" "$once" "$timed" "$later" "$store" "$moving" <<'PY'
import sys
b, w, h = sys.argv[1:4]
once, timed, later, store, moving = (int(x) for x in sys.argv[4:9])
extra = timed - once
print(f"{b} {w}x{h}, instructions of the pass (shadeToStore): once {once / 1e6:,.0f} M, in time {timed / 1e6:,.0f} M, ratio {timed / once:.3f}")
for name, n in [("extra", extra), ("  the later times (shadeInTime)", later), ("  writing the store's later colours (StoreWriter::close)", store),
                ("  the rest (first time's extra rays, candidate tests)", extra - later - store), ("rays through the moving scene, every time", moving)]:
    print(f"  {name:58s} {n / 1e6:9,.0f} M  {n / extra:6.1%} of the extra")
PY
  done
  exit 0
fi
for ((i = 0; i < rounds; ++i)); do
  for b in "${builds[@]}"; do
    once=$(bench "$b" "$threads" once | grep -oE '[0-9.]+ s cpu' | cut -d' ' -f1)
    timed=$(bench "$b" "$threads" $timed_label | grep -oE '[0-9.]+ s cpu' | cut -d' ' -f1)
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

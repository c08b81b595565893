#!/usr/bin/env bash
# Re-sampler benchmark (issue 5 and 6 figures): the 1920x1080 bench scene of >= 5 M micropolygons
# moving up to 50 px, 16 spp, gaussian 2x2; full shutter, quarter shutter, the same scene with its
# motion removed, a scene with transparency, and an interlaced frame against a progressive one and
# the two-pass reference. Prints one table row per run: wall seconds, samples/s per core, sample
# tests, hits, sample-test efficiency, peak RSS, and CPU seconds (what to compare on a shared
# machine, where wall time depends on the neighbours). Not a test: run by hand, copy figures into
# bench/RESULTS.md.
#
# Usage: bench/resample_bench.sh [BUILD_DIR] [MICROPOLYGONS]   (default build, 5000000)
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
mp=${2:-5000000}
bin="$build/reshutter"
work=$(mktemp -d /tmp/reshutter-bench.XXXXXX)
trap 'rm -rf "$work"' EXIT

"$bin" -q generate -n "$mp" -o "$work/moving.0001.mps"
"$bin" -q generate -n "$mp" --motion 0 --knots 1 -o "$work/static.0001.mps"
"$bin" -q generate -n "$mp" --transparent 0.3 -o "$work/transparent.0001.mps"

source bench/host.sh
host_line
printf "| run | wall s | CPU s | M samples per CPU-second | sample tests | hits | STE | peak RSS MB |\n|---|---|---|---|---|---|---|---|\n"
run() {  # name, reshutter arguments...
  local name=$1
  shift
  local out rss wall tests hits ste samples
  out=$({ /usr/bin/time -f "RSS %M CPU %U %S" "$bin" "$@" --stats -o "$work/out.exr" 2>&1; } 2>&1)
  rss=$(awk '/^RSS/ {printf "%.0f", $2 / 1024}' <<<"$out")
  cpu=$(awk '/^RSS/ {printf "%.2f", $4 + $5}' <<<"$out")
  wall=$(awk '/^  wall/ {s += $2} END {printf "%.2f", s}' <<<"$out")
  samples=$(awk '/^  samples/ {s += $2} END {print s}' <<<"$out")
  tests=$(awk '/^  sample tests/ {s += $3} END {print s}' <<<"$out")
  hits=$(awk '/^  hits/ {s += $2} END {print s}' <<<"$out")
  ste=$(awk -v h="$hits" -v t="$tests" 'BEGIN {printf "%.3f", t ? h / t : 0}')
  printf "| %s | %s | %s | %.2f | %s | %s | %s | %s |\n" "$name" "$wall" "$cpu" "$(awk -v s="$samples" -v c="$cpu" 'BEGIN {print s / c / 1e6}')" \
    "$tests" "$hits" "$ste" "$rss"
}
common=(--spp 16 --filter gaussian:2x2)
run "full shutter [0,1]" resample "$work/moving.0001.mps" "${common[@]}"
run "quarter shutter [0.25,0.5]" resample "$work/moving.0001.mps" "${common[@]}" --shutter 0.25:0.5
run "instant 0.5" resample "$work/moving.0001.mps" "${common[@]}" --shutter 0.5:0.5
run "motion removed (static path)" resample "$work/static.0001.mps" "${common[@]}"
run "30 % transparent grids" resample "$work/transparent.0001.mps" "${common[@]}"
# Interlacing: each field exposes a quarter frame (180-degree field shutter); one-row filter so the
# single pass is bit-identical to the two-pass reference.
field=(--spp 16 --filter gaussian:2x1)
run "progressive [0,0.25], gaussian 2x1" resample "$work/moving.0001.mps" "${field[@]}" --shutter 0:0.25
run "interlaced, one pass" fields "$work/moving.####.mps" --frames 1 "${field[@]}"
run "interlaced, two-pass reference" fields "$work/moving.####.mps" --frames 1 "${field[@]}" --two-pass

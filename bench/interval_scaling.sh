#!/usr/bin/env bash
# What a sub-interval costs against the whole shutter, as a function of how far the scene moves.
# For each motion length (the bench scene's generator: 1920x1080, ~1 px micropolygons in 16x16
# grids, random motion up to MOTION px over the dumped shutter), renders the full shutter, a half
# (0.25:0.75), a quarter (0.25:0.5) and the instant (0.5:0.5) at 16 spp, gaussian 2x2, and prints
# CPU seconds (whole process, best of ROUNDS; the PIZ write included), render wall, sample tests,
# hits, micropolygons drawn, and each interval's CPU as a fraction of the full shutter's.
# The question it answers: where does "a sub-interval costs roughly in proportion to its length"
# hold, and what is the interval-independent floor under it? Not a test: run by hand.
#
# Usage: bench/interval_scaling.sh [BUILD_DIR] [MICROPOLYGONS] [ROUNDS] [MOTIONS...]
#   defaults: build 5000000 2 0 12.5 25 50 100 200
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
mp=${2:-5000000}
rounds=${3:-2}
shift $(($# < 3 ? $# : 3))
motions=("$@")
((${#motions[@]})) || motions=(0 12.5 25 50 100 200)
bin="$build/reshutter"
work=$(mktemp -d /tmp/reshutter-scaling.XXXXXX)
trap 'rm -rf "$work"' EXIT

source bench/host.sh
host_line
printf "| motion px | interval | CPU s | / full | render wall s | sample tests | hits | STE | drawn micropolygons |\n"
printf "|---|---|---|---|---|---|---|---|---|\n"
for motion in "${motions[@]}"; do
  "$bin" -q generate -n "$mp" --motion "$motion" -o "$work/scene.mps"
  full_cpu=""
  for interval in 0:1 0.25:0.75 0.25:0.5 0.5:0.5; do
    best=""
    for ((r = 0; r < rounds; ++r)); do
      out=$({ /usr/bin/time -f "CPU %U %S" "$bin" resample "$work/scene.mps" --spp 16 --filter gaussian:2x2 \
        --shutter "$interval" --stats -o "$work/out.exr" 2>&1; } 2>&1)
      cpu=$(awk '/^CPU/ {printf "%.2f", $2 + $3}' <<<"$out")
      if [[ -z $best ]] || awk -v a="$cpu" -v b="$best" 'BEGIN {exit !(a < b)}'; then
        best=$cpu
        wall=$(awk '/^  wall/ {printf "%.2f", $2}' <<<"$out")
        tests=$(awk '/^  sample tests/ {print $3}' <<<"$out")
        hits=$(awk '/^  hits/ {print $2}' <<<"$out")
        # Drawn: on the static path plus bounded from their interval ends (the moving path).
        drawn=$(sed -n 's/.*processed (\([0-9]*\) on the static path, \([0-9]*\) bounded.*/\1 \2/p' <<<"$out" | awk '{print $1 + $2}')
      fi
    done
    [[ $interval == 0:1 ]] && full_cpu=$best
    ratio=$(awk -v a="$best" -v b="$full_cpu" 'BEGIN {printf "%.2f", a / b}')
    ste=$(awk -v h="$hits" -v t="$tests" 'BEGIN {printf "%.3f", t ? h / t : 0}')
    printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n" "$motion" "$interval" "$best" "$ratio" "$wall" "$tests" "$hits" "$ste" "$drawn"
  done
done

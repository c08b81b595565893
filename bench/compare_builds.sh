#!/usr/bin/env bash
# A/B timing of two reshutter binaries on a shared, noisy machine: runs them interleaved (A B A B
# ...), one thread each, and prints every run's user CPU seconds with the min and median, so a
# change is judged against its baseline measured in the same minutes. With --cachegrind, prints
# instead cachegrind's instruction and simulated L1/L2 miss counts (this VM's 32 KB 8-way L1d and
# 1 MB L2), which do not move with the neighbours' load. Not a test: run by hand.
#
# Usage: bench/compare_builds.sh [--reps N] [--cachegrind] BIN_A BIN_B STORE [resample arguments...]
#   e.g. bench/compare_builds.sh --reps 5 /tmp/base/reshutter build/reshutter moving.0001.mps \
#          --spp 16 --filter gaussian:2x2 --crop 480 1440 270 810
set -euo pipefail
reps=5
cachegrind=0
while [[ $# -gt 0 && $1 == --* ]]; do
  case "$1" in
    --reps) reps=$2; shift 2 ;;
    --cachegrind) cachegrind=1; shift ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
[[ $# -ge 3 ]] || { sed -n 2,10p "$0" >&2; exit 2; }
a=$1 b=$2 store=$3
shift 3
work=$(mktemp -d /tmp/reshutter-compare.XXXXXX)
trap 'rm -rf "$work"' EXIT

if [[ $cachegrind == 1 ]]; then
  for bin in "$a" "$b"; do
    echo "$bin"
    valgrind --tool=cachegrind --cache-sim=yes --D1=32768,8,64 --LL=1048576,8,64 --cachegrind-out-file="$work/cg.out" \
      "$bin" -q -j 1 resample "$store" -o "$work/out.exr" "$@" 2>&1 | grep -E "I +refs|D1 +misses|LL +misses"
  done
  exit 0
fi

declare -A runs
for ((i = 0; i < reps; ++i)); do
  for bin in "$a" "$b"; do
    /usr/bin/time -o "$work/time" -f "%U" "$bin" -q -j 1 resample "$store" -o "$work/out.exr" "$@"
    runs[$bin]="${runs[$bin]:-} $(cat "$work/time")"
  done
done
for bin in "$a" "$b"; do
  read -ra t <<<"${runs[$bin]}"
  sorted=$(printf "%s\n" "${t[@]}" | sort -g | tr '\n' ' ')
  read -ra s <<<"$sorted"
  echo "$bin: user s min ${s[0]}, median ${s[$(( ${#s[@]} / 2 ))]} (runs:${runs[$bin]})"
done

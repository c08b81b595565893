#!/usr/bin/env bash
# Depth of field's cost as a ratio measured in pairs: each round runs the 1080p bench store's
# pinhole frame and then its frame through bench/dof_frame.sh's lens of RADIUS px, back to back, and
# takes the ratio of the two (wall and CPU); prints every round's ratios sorted and their medians,
# for each binary given (interleaved round by round). On a host whose speed drifts over minutes a
# ratio within one round moves less than a ratio of two "fastest of N" times taken minutes apart.
# Not a test: run by hand.
# Usage: bench/dof_pairs.sh STORE ROUNDS RADIUS BINARY...
set -euo pipefail
store=${1:?usage: bench/dof_pairs.sh STORE ROUNDS RADIUS BINARY...}
rounds=${2:?usage}
radius=${3:?usage}
shift 3
(($# >= 1)) || { echo "usage: bench/dof_pairs.sh STORE ROUNDS RADIUS BINARY..." >&2; exit 2; }
work=$(mktemp -d /tmp/reshutter-dofpairs.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
source "$(dirname "$0")/lens.sh"
host_line
mapfile -t lens < <(lens_options "$radius")
run() {  # binary, then lens options: "wall cpu"
  local bin=$1
  shift
  /usr/bin/time -o "$work/time" -f "%e %U %S" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 -o "$work/out.exr" "$@" > /dev/null 2>&1
  awk '{ print $1, $2 + $3 }' "$work/time"
}
for ((round = 0; round < rounds; ++round)); do
  for bin in "$@"; do
    read -r pw pc < <(run "$bin" --pinhole)
    read -r lw lc < <(run "$bin" "${lens[@]}")
    echo "$bin $(awk -v a="$lw" -v b="$pw" 'BEGIN { printf "%.3f", a / b }') $(awk -v a="$lc" -v b="$pc" 'BEGIN { printf "%.3f", a / b }') $pw $lw"
  done
done > "$work/pairs"
median() { sort -n | awk '{ v[NR] = $1 } END { printf "%.3f", NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
for bin in "$@"; do
  echo "$bin ($radius px, $rounds rounds)"
  echo "  wall ratios $(awk -v b="$bin" '$1 == b { print $2 }' "$work/pairs" | sort -n | tr '\n' ' ')  median $(awk -v b="$bin" '$1 == b { print $2 }' "$work/pairs" | median)"
  echo "  CPU ratios  $(awk -v b="$bin" '$1 == b { print $3 }' "$work/pairs" | sort -n | tr '\n' ' ')  median $(awk -v b="$bin" '$1 == b { print $3 }' "$work/pairs" | median)"
  echo "  pinhole wall s $(awk -v b="$bin" '$1 == b { print $4 }' "$work/pairs" | sort -n | tr '\n' ' '); lens wall s $(awk -v b="$bin" '$1 == b { print $5 }' "$work/pairs" | sort -n | tr '\n' ' ')"
done

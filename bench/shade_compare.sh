#!/usr/bin/env bash
# What a change to splitting or dicing costs: micropolygons, grids and shading CPU (user + system,
# best of ROUNDS) of every scene in ../shared/data/rib and rib-production, and of the Utah teapot
# at shading rates 1 and 8, shaded by two builds of reshutter one after the other.
#   bench/shade_compare.sh OLD_BINARY NEW_BINARY [rounds=3]
set -euo pipefail
cd "$(dirname "$0")/.."
old=$1 new=$2 rounds=${3:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
scenes=()
for f in ../shared/data/rib/*.rib ../shared/data/rib-production/*.rib; do scenes+=("$f"); done
teapot=$(cd ../shared/data/rib-production/rmr_arman_ch12 && pwd)/teapot.rib
for rate in 1 8; do
  printf 'Format 640 480 1\nProjection "perspective" "fov" [30]\nTranslate 0 -0.5 11\nRotate -100 1 0 0\nRotate 30 0 0 1\nWorldBegin\nShadingRate %s\nSurface "constant"\nReadArchive "%s"\nWorldEnd\n' \
    "$rate" "$teapot" > "$work/teapot_rate$rate.rib"
  scenes+=("$work/teapot_rate$rate.rib")
done
# One figure per build: the first frame's micropolygons and grids, CPU seconds summed over frames.
measure() {
  local bin=$1 scene=$2 best="" out
  for r in $(seq "$rounds"); do
    (cd "$(dirname "$scene")" && /usr/bin/time -f "%U %S" -o "$work/time" "$bin" -q shade "$(basename "$scene")" -o "$work/out.####.mps" > "$work/out.txt")
    t=$(awk '{ printf "%.3f", $1 + $2 }' "$work/time")
    if [ -z "$best" ] || awk -v a="$t" -v b="$best" 'BEGIN { exit !(a < b) }'; then best=$t; fi
  done
  out=$(sed -n '1s/^frame [^:]*: \([0-9,]*\) micropolygons in \([0-9,]*\) grids.*/\1 \2/p' "$work/out.txt" | tr -d ,)
  echo "$out $best"
}
echo "$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); best of $rounds"
printf "%-28s %12s %12s %7s %8s %8s %8s %7s\n" scene "mps old" "mps new" ratio "grids o" "grids n" "cpu o" "cpu n"
for s in "${scenes[@]}"; do
  read -r mo go to <<< "$(measure "$(realpath "$old")" "$s")"
  read -r mn gn tn <<< "$(measure "$(realpath "$new")" "$s")"
  printf "%-28s %12s %12s %7.3f %8s %8s %8s %7s\n" "$(basename "$s" .rib)" "$mo" "$mn" "$(awk -v a="$mn" -v b="$mo" 'BEGIN { print a / b }')" "$go" "$gn" "$to" "$tn"
done

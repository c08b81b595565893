#!/usr/bin/env bash
# Depth of field, two builds against each other: the 1080p bench store through bench/dof_frame.sh's
# apertures (circles of confusion of RADII px at the far depth; 0 = the pinhole), each build and
# radius run ROUNDS times interleaved in the same minutes, and the fastest of each reported (wall
# and CPU seconds, rasterize thread-seconds) with the wall and CPU ratios to that build's pinhole
# frame (the CPU ratio moves less with the host's speed). On a noisy host only ratios within one
# run mean anything. Not a test: run by hand.
# Usage: bench/dof_ab.sh OLD_BINARY NEW_BINARY STORE ROUNDS [RADII...]
set -euo pipefail
old=${1:?usage: bench/dof_ab.sh OLD_BINARY NEW_BINARY STORE ROUNDS [RADII...]}
new=${2:?usage}
store=${3:?usage}
rounds=${4:?usage}
shift 4
radii=("$@")
((${#radii[@]})) || radii=(0 5 20 50)
work=$(mktemp -d /tmp/reshutter-dofab.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
source "$(dirname "$0")/lens.sh"
host_line
for ((round = 0; round < rounds; ++round)); do
  for r in "${radii[@]}"; do
    for which in old new; do
      bin=$old
      [[ $which == new ]] && bin=$new
      mapfile -t lens < <(lens_options "$r")
      /usr/bin/time -o "$work/time" -f "%e %U %S" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 --stats -o "$work/out.exr" "${lens[@]}" > "$work/log" 2>&1
      raster=$(awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "rasterize") print $(i + 1) }' "$work/log")
      echo "$which $r $(cat "$work/time") $raster"
    done
  done
done | awk '{ k = $1 " " $2; cpu = $4 + $5
              if (!(k in w) || $3 < w[k]) w[k] = $3
              if (!(k in c) || cpu < c[k]) c[k] = cpu
              if (!(k in ras) || $6 < ras[k]) ras[k] = $6 }
            END { for (k in w) { split(k, p, " "); printf "%s %4s px   wall %7.2f s (%4.2fx)   CPU %7.2f s (%4.2fx)   rasterize %8.3f thread-s\n", p[1], p[2], w[k], w[k] / w[p[1] " 0"], c[k], c[k] / c[p[1] " 0"], ras[k] } }' | sort -k1,1r -k2n

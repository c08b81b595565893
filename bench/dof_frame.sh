#!/usr/bin/env bash
# What depth of field costs: the 1080p bench store re-sampled through a thin lens (16 spp, gaussian
# 2×2, PIZ write) focused on the scene's nearest depth (5), with the aperture chosen so that the
# circle of confusion at its farthest depth (50) has a radius of 0 (the pinhole), 5, 20 and 50
# pixels: wall and CPU seconds, rasterize thread-seconds, sample-test efficiency (hits / tests),
# the samples the lens path searched per micropolygon (its cost driver) and the ratio to the
# pinhole frame. Not a test: run by hand.
# Usage: bench/dof_frame.sh BUILD_DIR STORE [RADII...]
#   (stores: reshutter generate -n 5000000 -o moving.0001.mps, and with --motion 0 --knots 1)
set -euo pipefail
build=${1:?usage: bench/dof_frame.sh BUILD_DIR STORE [RADII...]}
store=${2:?usage: bench/dof_frame.sh BUILD_DIR STORE [RADII...]}
shift 2
radii=("$@")
((${#radii[@]})) || radii=(0 5 20 50)
bin=$build/reshutter
work=$(mktemp -d /tmp/reshutter-dof.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
source "$(dirname "$0")/lens.sh"
host_line
pinhole=""
for r in "${radii[@]}"; do
  mapfile -t lens < <(lens_options "$r")
  /usr/bin/time -o "$work/time" -f "%e %U %S %M" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 --stats -o "$work/out.exr" "${lens[@]}" > "$work/log" 2>&1
  read -r wall user sys rss < "$work/time"
  raster=$(awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "rasterize") print $(i + 1) }' "$work/log")
  eff=$(awk '/test efficiency/ { print $3 }' "$work/log")
  tests=$(awk '/sample tests/ { print $3 }' "$work/log")
  scanned=$(sed -n 's/.*search boxes (\([0-9.]*\) each).*/\1/p' "$work/log")
  [[ -z $pinhole ]] && pinhole=$wall
  printf 'CoC radius %3s px   wall %8.2f s (%5.1fx)   CPU %8.2f s   rasterize %9s thread-s   tests %11s   efficiency %s   searched %6s per micropolygon   peak RSS %5d MB\n' \
    "$r" "$wall" "$(awk -v a="$wall" -v b="$pinhole" 'BEGIN { print a / b }')" "$(awk -v u="$user" -v s="$sys" 'BEGIN { print u + s }')" "$raster" "$tests" "$eff" "${scanned:--}" $((rss / 1024))
done

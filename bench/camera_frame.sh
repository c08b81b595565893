#!/usr/bin/env bash
# What another camera costs: the 1080p bench store (16 spp, gaussian 2×2, PIZ write) rendered from
# the camera it was made for and from cameras moved sideways by BASELINE (the right eye of a
# parallel stereo rig twice that wide; --look-from, so every part is carried into the new camera's
# space), turned by 10 degrees about the vertical axis, and cameras that move over the shutter -
# trucking 0.2 sideways and panning 10 degrees (every part is then carried at its knots and the
# camera's motion times: a still part moves). Wall and CPU seconds, the parts
# fetched and carried, rasterize thread-seconds and the ratio to the first camera's frame, best of
# ROUNDS interleaved runs. Not a test: run by hand.
# Usage: bench/camera_frame.sh BUILD_DIR STORE [ROUNDS]
#   (stores: reshutter generate -n 5000000 -o moving.0001.mps, and with --motion 0 --knots 1)
set -euo pipefail
build=${1:?usage: bench/camera_frame.sh BUILD_DIR STORE [ROUNDS]}
store=${2:?usage: bench/camera_frame.sh BUILD_DIR STORE [ROUNDS]}
rounds=${3:-3}
bin=$build/reshutter
work=$(mktemp -d /tmp/reshutter-camera.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
host_line
# The synthetic scene lies at depths 5 to 50 in front of a camera at the origin looking down +z
# (fov 40 over 1080 rows: a = 540 / tan 20° = 1484 px per unit of x/z), so a baseline b shifts
# the nearest micropolygons by 1484 b / 5 px and the farthest by 1484 b / 50.
names=("first camera" "moved 0.05 (15 px near, 1.5 far)" "moved 0.2 (59 px near, 6 far)" "moved 1 (297 px near, 30 far)" "turned 10 degrees"
       "trucking 0 to 0.2 over the shutter" "panning 10 degrees over the shutter")
views=("" "--look-from 0.05,0,0 --look-at 0.05,0,1" "--look-from 0.2,0,0 --look-at 0.2,0,1" "--look-from 1,0,0 --look-at 1,0,1"
       "--look-from 0,0,0 --look-at 0.17364818,0,0.98480775" "--look-from 0,0,0,0.2,0,0 --look-at 0,0,1,0.2,0,1"
       "--look-from 0,0,0 --look-at 0,0,1,0.17364818,0,0.98480775")
declare -A best
for ((round = 0; round < rounds; ++round)); do
  for i in "${!views[@]}"; do
    # shellcheck disable=SC2086
    /usr/bin/time -o "$work/time" -f "%e %U %S %M" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 --stats -o "$work/out.exr" ${views[$i]} > "$work/log.$i" 2>&1
    read -r wall user sys rss < "$work/time"
    if [[ -z ${best[$i]:-} ]] || awk -v a="$wall" -v b="${best[$i]%% *}" 'BEGIN { exit !(a < b) }'; then
      raster=$(awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "rasterize") print $(i + 1) }' "$work/log.$i")
      fetched=$(awk '/^  parts  / { print $2 }' "$work/log.$i")
      carried=$(sed -n 's/.*, \([0-9]*\) carried into.*/\1/p' "$work/log.$i")
      best[$i]="$wall $(awk -v u="$user" -v s="$sys" 'BEGIN { print u + s }') $raster $fetched ${carried:-0} $((rss / 1024))"
    fi
  done
done
first=${best[0]%% *}
for i in "${!views[@]}"; do
  read -r wall cpu raster fetched carried rss <<< "${best[$i]}"
  printf '%-36s wall %6.2f s (%4.2fx)   CPU %6.2f s   rasterize %6s thread-s   parts %6s fetched, %6s carried   peak RSS %5d MB\n' \
    "${names[$i]}" "$wall" "$(awk -v a="$wall" -v b="$first" 'BEGIN { print a / b }')" "$cpu" "$raster" "$fetched" "$carried" "$rss"
done

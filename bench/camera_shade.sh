#!/usr/bin/env bash
# What shading for a stereo pair costs: each RIB scene shaded for its own camera, then kept and
# diced for a stereo pair around it as well (shade --stereo BASELINE), and with the view-dependent
# terms' inputs (--view-dependent): best-of-ROUNDS wall seconds, micropolygons, store bytes, the
# geometry detail expansion the pass reports, and the ratios. Not a test: run by hand.
# Usage: bench/camera_shade.sh BUILD_DIR BASELINE ROUNDS SCENE.rib...
set -euo pipefail
build=${1:?usage: bench/camera_shade.sh BUILD_DIR BASELINE ROUNDS SCENE.rib...}
baseline=${2:?usage: bench/camera_shade.sh BUILD_DIR BASELINE ROUNDS SCENE.rib...}
rounds=${3:?usage: bench/camera_shade.sh BUILD_DIR BASELINE ROUNDS SCENE.rib...}
shift 3
bin=$build/reshutter
work=$(mktemp -d /tmp/reshutter-camshade.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
host_line
for scene in "$@"; do
  first=""
  for mode in "one camera" "stereo pair" "stereo pair, view-dependent inputs"; do
    args=()
    [[ $mode != "one camera" ]] && args+=(--stereo "$baseline")
    [[ $mode == *inputs ]] && args+=(--view-dependent)
    best=""
    for ((r = 0; r < rounds; ++r)); do
      /usr/bin/time -o "$work/time" -f "%e" "$bin" shade "$scene" -o "$work/s.mps" "${args[@]}" > "$work/log" 2> /dev/null
      wall=$(cat "$work/time")
      if [[ -z $best ]] || awk -v a="$wall" -v b="$best" 'BEGIN { exit !(a < b) }'; then best=$wall; fi
    done
    [[ -z $first ]] && first=$best
    mps=$(sed -n 's/^frame [0-9]*: \([0-9,]*\) micropolygons.*/\1/p' "$work/log" | head -1)
    expansion=$(sed -n 's/.*geometry detail expansion \([0-9.]*\).*/\1/p' "$work/log")
    printf '%-28s %-36s wall %6.2f s (%4.2fx)   %12s micropolygons   %10d bytes   expansion %s\n' "$(basename "$scene")" "$mode" "$best" \
      "$(awk -v a="$best" -v b="$first" 'BEGIN { print a / b }')" "$mps" "$(stat -c %s "$work/s.mps")" "${expansion:-1}"
  done
done

#!/usr/bin/env bash
# A volume's share of a whole frame: the 1080p bench store (5 M moving micropolygons, 16 spp,
# gaussian 2×2, PIZ write) re-sampled without a volume, then with a procedural smoke puff of
# RESOLUTION³ voxels in front of it (`reshutter smoke`, centred on the view): shared rays (the
# default, a ray per pixel), shared rays with empty-space skipping off, and every sample marching
# its own ray (with and without skipping, unless --no-per-sample); wall seconds, resolve
# thread-seconds (where volumes are marched), density lookups and peak RSS. Not a test: run by hand.
# Usage: bench/volume_frame.sh BUILD_DIR STORE [RESOLUTION] [--no-per-sample]
#   (store: reshutter generate -n 5000000 -o moving.0001.mps)
set -euo pipefail
build=${1:?usage: bench/volume_frame.sh BUILD_DIR STORE [RESOLUTION]}
store=${2:?usage: bench/volume_frame.sh BUILD_DIR STORE [RESOLUTION]}
res=${3:-256}
perSample=1
[[ ${4:-} == --no-per-sample ]] && perSample=0
bin=$build/reshutter
work=$(mktemp -d /tmp/reshutter-volframe.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
host_line
# The synthetic store's camera looks down +z from the origin (fov 40) at depths 5 to 50: a puff
# of radius 2 at depth 12 covers about a sixth of the frame.
"$bin" -q smoke -o "$work/smoke.vdb" --center 0 0 12 --radius 2 --resolution "$res"
run() {  # LABEL EXTRA...
  local label=$1; shift
  /usr/bin/time -o "$work/time" -f "%e %M" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 --stats -o "$work/out.exr" "$@" > "$work/log" 2>&1
  read -r wall rss < "$work/time"
  resolve=$(awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "resolve") print $(i + 1) }' "$work/log")
  lookups=$(sed -n 's/.*marched, \([0-9]*\) density lookups.*/\1/p' "$work/log")
  printf '%-40s wall %7.2f s   resolve %8s thread-s   lookups %12s   peak RSS %5d MB\n' "$label" "$wall" "$resolve" "${lookups:-0}" $((rss / 1024))
}
run "no volume"
run "smoke ${res}^3, shared rays" --volume "$work/smoke.vdb,density-scale=1.5"
run "smoke ${res}^3, shared rays, no skipping" --volume "$work/smoke.vdb,density-scale=1.5" --volume-no-skip
if ((perSample)); then
  run "smoke ${res}^3, a ray per sample" --volume "$work/smoke.vdb,density-scale=1.5" --volume-ray-spacing 0
  run "smoke ${res}^3, a ray per sample, no skipping" --volume "$work/smoke.vdb,density-scale=1.5" --volume-ray-spacing 0 --volume-no-skip
fi

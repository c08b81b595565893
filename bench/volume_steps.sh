#!/usr/bin/env bash
# Volume accuracy against time: the demo store with its smoke puff re-sampled at several ray-march
# steps (voxels), each image against a reference at a quarter of the finest step (RMS and max
# error over R G B A, by oiiotool --diff), with the resolve stage's thread-seconds (where the
# volume is marched) and the wall time; then empty-space skipping on and off. Not a test: run by
# hand. Usage: bench/volume_steps.sh BUILD_DIR [WORK_DIR]
set -euo pipefail
build=${1:?usage: bench/volume_steps.sh BUILD_DIR [WORK_DIR]}
work=${2:-$(mktemp -d /tmp/reshutter-volume.XXXXXX)}
bin=$build/reshutter
source "$(dirname "$0")/host.sh"
host_line
[[ -f $work/demo.mps && -f $work/smoke.vdb ]] || "$bin" demo --output "$work" >/dev/null
vol="$work/smoke.vdb,density-scale=3,albedo=0.9:0.9:0.9"
crop=(--crop 120 320 60 260)  # the puff and what lies behind it
render() {  # OUT EXTRA...: prints resolve thread-s and wall s
  local out=$1; shift
  "$bin" -q resample "$work/demo.mps" --volume "$vol" "${crop[@]}" --stats -o "$out" "$@" 2>&1 |
    awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "resolve") r = $(i + 1) } /^  wall/ { w = $2 } END { print r, w }'
}
render "$work/ref.exr" --volume-step 0.0625 >/dev/null
printf '%-22s %10s %10s %12s %10s\n' "step (voxels)" "RMS error" "max error" "resolve s" "wall s"
for step in 0.25 0.5 1 2 4; do
  read -r resolve wall < <(render "$work/step.exr" --volume-step "$step")
  diff=$(oiiotool "$work/step.exr" --ch R,G,B,A "$work/ref.exr" --ch R,G,B,A --diff 2>&1 || true)
  rms=$(sed -n "s/.*RMS error = *\([0-9.e+-]*\).*/\1/p" <<<"$diff")
  max=$(sed -n "s/.*Max error *= *\([0-9.e+-]*\).*/\1/p" <<<"$diff")
  printf '%-22s %10s %10s %12s %10s\n' "$step" "${rms:-0}" "${max:-0}" "$resolve" "$wall"
done
for flag in "" --volume-no-skip; do
  read -r resolve wall < <(render "$work/skip.exr" $flag)
  printf '%-34s resolve %8s s, wall %6s s\n' "${flag:-default (skip, cached light)}" "$resolve" "$wall"
done
read -r resolve wall < <("$bin" -q resample "$work/demo.mps" "${crop[@]}" --stats -o "$work/none.exr" 2>&1 |
  awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "resolve") r = $(i + 1) } /^  wall/ { w = $2 } END { print r, w }')
printf '%-34s resolve %8s s, wall %6s s\n' "no volume" "$resolve" "$wall"

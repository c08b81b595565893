#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + UBSan) and runs one.
#   scripts/fuzz.sh store [seconds] [--fast]    fuzz the .mps reader
#   scripts/fuzz.sh rib [seconds] [--fast]      fuzz the RIB parser, scene interpreter, splitting and dicing
#   scripts/fuzz.sh farm [seconds] [--fast]     fuzz the farm's job description reader (job.txt)
# Findings land in build-fuzz/findings-<target>/; minimise them and copy them into
# tests/corpus/<target>/, where the regression tests replay them on every test run.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh
target=${1:-store}
seconds=${2:-300}
# --fast: UndefinedBehaviorSanitizer only (several times the executions per second of ASan +
# UBSan; a crash is still a finding, a silent heap overrun is not), in build-fuzz-fast.
sanitizers=address,undefined build=build-fuzz
if [ "${3:-}" = --fast ]; then sanitizers=undefined build=build-fuzz-fast; fi
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRESHUTTER_FUZZ=ON -DRESHUTTER_BENCH=OFF \
  -DRESHUTTER_FUZZ_SANITIZERS="$sanitizers" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ >/dev/null
name=fuzz_${target}_reader
[ "$target" = farm ] && name=fuzz_farm_job
ninja -C "$build" "$name" $( [ "$target" = store ] && echo reshutter ) >/dev/null
bin=$build/$name
work=$build/work-$target
mkdir -p "$work/corpus" "$build/findings-$target"
cp tests/corpus/$target/* "$work/corpus/" 2>/dev/null || true
if [ "$target" = rib ]; then
  # Seeds: the real RIB files (read in place, never copied into the repository).
  cp ../shared/data/rib/*.rib ../shared/data/rib-production/*.rib "$work/corpus/" 2>/dev/null || true
fi
if [ "$target" = store ]; then
  # Seeds: small valid stores of several shapes, each behind a mode byte (0x01 = repair checksums).
  for args in "-n 300 --width 64 --height 48" "-n 600 --knots 3 --width 40 --height 40 --transparent 0.5" \
              "-n 256 --knots 1 --width 32 --height 32 --color-codec half --opacity-codec unorm16"; do
    f=$(mktemp "$work/seed-XXXX.mps"); rm -f "$f"
    "$build"/reshutter -q generate $args -o "$f"
    { printf '\x01'; cat "$f"; } > "$work/corpus/seed-$(basename "$f")"
    rm -f "$f"
  done
  # A format-5 store (recorded lights, a scene volume, a lens and a moving second camera), shaded
  # from a tiny RIB.
  "$build"/reshutter -q smoke -o "$work/seed.vdb" --radius 1 --resolution 8
  cat > "$work/seed.rib" <<RIB
Format 24 16 1
Projection "perspective" "fov" [50]
Shutter 0 1
DepthOfField 2.8 0.5 5
MotionBegin [0 0.5 1]
Rotate 0 0 1 0
Rotate 4 0 1 0
Rotate 10 0 1 0
MotionEnd
Camera "pan"
Identity
WorldBegin
LightSource "pointlight" 1 "from" [0 2 0] "intensity" [4]
LightSource "distantlight" 2 "to" [0 0 1]
Surface "plastic"
Polygon "P" [-2 -2 6  2 -2 6  2 2 6  -2 2 6]
AttributeBegin
MotionBegin [0 1]
Translate 0 0 4
Translate 0.3 0 4
MotionEnd
Volume "blobbydso:impl_openvdb" [-1 1 -1 1 -1 1] [0 0 0] "constant string[2] blobbydso:stringargs" ["$work/seed.vdb" "density"]
AttributeEnd
WorldEnd
RIB
  "$build"/reshutter -q shade "$work/seed.rib" -o "$work/seed-v5.mps"
  { printf '\x01'; cat "$work/seed-v5.mps"; } > "$work/corpus/seed-v5.mps"
  rm -f "$work/seed-v5.mps" "$work/seed.rib"
fi
"$bin" -max_total_time="$seconds" -max_len=65536 -timeout=10 -rss_limit_mb=2048 \
  -artifact_prefix="$build/findings-$target/" "$work/corpus" 2>&1 | tail -n 5
echo "findings: $(ls "$build/findings-$target" | wc -l) ($build/findings-$target/)"

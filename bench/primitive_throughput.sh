#!/usr/bin/env bash
# Shading-pass throughput of the production surfaces against polygons: one wavy N x N control grid
# shaded as PointsPolygons (bilinear quads), as a bicubic B-spline PatchMesh and as a Catmull-Clark
# SubdivisionMesh (interpolateboundary), same camera and shading rate; micropolygons per CPU-second
# of `reshutter shade` (user + system time, so the figure does not depend on the core count).
#   bench/primitive_throughput.sh [build/reshutter] [N=64] [rounds=3]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-build/reshutter}
n=${2:-64}
rounds=${3:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
points() { awk -v n="$n" 'BEGIN { for (j = 0; j < n; j++) for (i = 0; i < n; i++) {
  x = -1 + 2 * i / (n - 1); y = -1 + 2 * j / (n - 1); printf "%.6f %.6f %.6f ", x, y, 0.15 * sin(6 * x) * cos(5 * y) } }'; }
faces() { awk -v n="$n" -v what="$1" 'BEGIN { for (j = 0; j + 1 < n; j++) for (i = 0; i + 1 < n; i++) {
  if (what == "counts") printf "4 "; else printf "%d %d %d %d ", j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i } }'; }
head="Format 1920 1080 1\nProjection \"perspective\" \"fov\" [40]\nShadingRate 1\nTranslate 0 0 3.2\nRotate -35 1 0 0\nWorldBegin\nLightSource \"distantlight\" 1\nSurface \"plastic\"\n"
P=$(points)
printf "$head" > "$work/polygons.rib"; echo "PointsPolygons [$(faces counts)] [$(faces verts)] \"P\" [$P]" >> "$work/polygons.rib"
printf "$head" > "$work/patches.rib"; echo "Basis \"b-spline\" 1 \"b-spline\" 1 PatchMesh \"bicubic\" $n \"nonperiodic\" $n \"nonperiodic\" \"P\" [$P]" >> "$work/patches.rib"
printf "$head" > "$work/subdivision.rib"
echo "SubdivisionMesh \"catmull-clark\" [$(faces counts)] [$(faces verts)] [\"interpolateboundary\"] [1 0] [1] [] \"P\" [$P]" >> "$work/subdivision.rib"
for f in polygons patches subdivision; do echo WorldEnd >> "$work/$f.rib"; done
echo "$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); control grid ${n}x${n}"
for f in polygons patches subdivision; do
  best=""
  for r in $(seq "$rounds"); do
    /usr/bin/time -f "%U %S" -o "$work/time" "$bin" -q shade "$work/$f.rib" -o "$work/$f.mps" > "$work/$f.out"
    mps=$(sed -n 's/^frame [^:]*: \([0-9,]*\) micropolygons.*/\1/p' "$work/$f.out" | tr -d ,)
    rate=$(awk -v m="$mps" '{ printf "%.0f", m / ($1 + $2) }' "$work/time")
    if [ -z "$best" ] || [ "$rate" -gt "$best" ]; then best=$rate; fi
  done
  printf "%-12s %10s micropolygons  %8.2f M micropolygons per CPU-second (best of %s)\n" "$f" "$mps" "$(awk -v b="$best" 'BEGIN { print b / 1e6 }')" "$rounds"
done

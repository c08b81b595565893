#!/usr/bin/env bash
# A contact sheet of every scene in ../shared/data/rib and ../shared/data/rib-production: each is
# shaded and re-sampled with its own settings, then reduced to a 240x180 thumbnail; the sheet goes
# to docs/gallery.png and a table of results and warnings to docs/gallery.md.
#   bench/gallery.sh [build/reshutter]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-build/reshutter}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
md=docs/gallery.md
{
  echo "# Gallery: the shared RIB scenes"
  echo
  echo "Every scene in \`../shared/data/rib\` and \`../shared/data/rib-production\`, shaded once and re-sampled over its own"
  echo "shutter (16 spp, gaussian filter) by \`bench/gallery.sh\`; the sheet reads left to right, top to bottom, in the"
  echo "order of the table. Made with \`$(git describe --always --dirty 2>/dev/null || echo unknown)\`."
  echo
  echo "![contact sheet](gallery.png)"
  echo
  echo "| # | scene | result | warnings (distinct, first three) |"
  echo "|---|---|---|---|"
} > "$md"
thumbs=()
i=0
for f in ../shared/data/rib/*.rib ../shared/data/rib-production/*.rib ../shared/data/rib-production/*/*.rib; do
  case "$f" in */teapot.rib) continue ;; esac  # fig12.7.rib's archive, not a scene
  i=$((i + 1))
  name=$(basename "$f" .rib)
  thumb="$work/$i.png"
  result=""
  if "$bin" shade "$f" -o "$work/$name.####.mps" > "$work/$name.out" 2> "$work/$name.err"; then
    store=$(ls "$work/$name".*.mps | head -n 1)
    "$bin" -q resample "$store" -o "$work/$name.exr" > /dev/null 2>> "$work/$name.err"
    oiiotool "$work/$name.exr" --ch R,G,B --colorconvert linear sRGB --fit:pad=1 240x180 -o "$thumb"
    result=$(sed -n 's/^frame \([^:]*\): \([0-9,]*\) micropolygons.*/frame \1: \2 micropolygons/p' "$work/$name.out" | head -n 1)
    skipped=$(sed -n 's/.*skipped primitives: //p' "$work/$name.out" | head -n 1)
    [ -n "$skipped" ] && result="$result; skipped $skipped"
  else
    oiiotool --create 240x180 3 --fill:color=0.5,0,0 0,0,240,180 -o "$thumb"
    result="error: $(grep -v 'warning:' "$work/$name.err" | tail -n 1 | sed 's/^reshutter: //')"
  fi
  warnings=$( (grep 'warning:' "$work/$name.err" || true) | grep -v 'more like this' | sed -e 's/^reshutter: warning: //' -e 's/^[^ ]*:[0-9]* ([A-Za-z]*): //' -e 's/^[^ ]*:[0-9]*: //' |
    sort -u | head -n 3 | tr '\n' '\t' | sed -e 's/\t$//' -e 's/\t/ · /g' -e 's/|/\\|/g' || true)
  count=$(grep -c 'warning:' "$work/$name.err" || true)
  echo "| $i | \`${f#../shared/data/}\` | $result | $count: ${warnings:-none} |" >> "$md"
  thumbs+=("$thumb")
done
cols=4
rows=$(((${#thumbs[@]} + cols - 1) / cols))
while ((${#thumbs[@]} < rows * cols)); do
  pad="$work/pad${#thumbs[@]}.png"
  oiiotool --create 240x180 3 -o "$pad"
  thumbs+=("$pad")
done
oiiotool "${thumbs[@]}" --mosaic:pad=4 ${cols}x${rows} -o docs/gallery.png
echo "wrote docs/gallery.png and $md (${i} scenes)"

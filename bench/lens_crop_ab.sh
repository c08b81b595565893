#!/usr/bin/env bash
# The lens path's rasterizer, builds (or settings) against each other on the centre crop of the
# 1080p bench frame through the 20 px lens of bench/dof_frame.sh, one thread: shorter than a whole
# frame and without the second thread's contention, so more interleaved rounds fit in the minutes a
# noisy host stays steady. Each configuration is NAME=BINARY or NAME=BINARY:VAR=VALUE[:VAR=VALUE...]
# (environment settings for that run); prints each one's rasterize thread-seconds sorted, and their
# median. Compare only configurations of one run. Not a test: run by hand.
# Usage: bench/lens_crop_ab.sh STORE ROUNDS NAME=BINARY[:VAR=VALUE...] ...
set -euo pipefail
store=${1:?usage: bench/lens_crop_ab.sh STORE ROUNDS NAME=BINARY[:VAR=VALUE...] ...}
rounds=${2:?usage}
shift 2
(($# >= 1)) || { echo "usage: bench/lens_crop_ab.sh STORE ROUNDS NAME=BINARY[:VAR=VALUE...] ..." >&2; exit 2; }
work=$(mktemp -d /tmp/reshutter-lenscrop.XXXXXX)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/host.sh"
host_line
for ((round = 0; round < rounds; ++round)); do
  for config in "$@"; do
    name=${config%%=*} rest=${config#*=}
    bin=${rest%%:*} setting=()
    [[ $rest == *:* ]] && IFS=: read -ra setting <<< "${rest#*:}"
    env "${setting[@]}" "$bin" -q -j 1 resample "$store" --spp 16 --filter gaussian:2x2 --fstop 6.676380 --focal-length 1 --focus-distance 5 \
      --crop 480 1440 270 810 --compression none --stats -o "$work/out.exr" > "$work/log" 2>&1
    echo "$name $(awk '/time \(thread-sum\)/ { for (i = 1; i <= NF; ++i) if ($i == "rasterize") print $(i + 1) }' "$work/log")"
  done
done | awk '{ times[$1] = times[$1] " " $2; order[$1] = order[$1] ? order[$1] : ++n; names[n] = $1 }
  END {
    for (i = 1; i <= n; ++i) {
      k = split(substr(times[names[i]], 2), t, " ")
      for (a = 1; a <= k; ++a) for (b = a + 1; b <= k; ++b) if (t[b] + 0 < t[a] + 0) { s = t[a]; t[a] = t[b]; t[b] = s }
      line = ""
      for (a = 1; a <= k; ++a) line = line " " t[a]
      printf "%-12s rasterize thread-s%s   median %s\n", names[i], line, t[int((k + 1) / 2)]
    }
  }'

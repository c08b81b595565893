#!/usr/bin/env bash
# Whole-frame A/B timing as a user runs it: both cores, PIZ write included. For each round and
# each case (full shutter, quarter 0.25:0.5, the instant 0.5:0.5, the motion-free store), runs A
# then B, and prints per case and binary the sorted wall seconds and the peak RSS. Interleaving
# puts both builds in the same minutes of a noisy machine. Not a test: run by hand.
#
# Usage: bench/whole_frames.sh [--rounds N] BIN_A BIN_B MOVING_STORE STATIC_STORE
#   e.g. bench/whole_frames.sh /tmp/base/reshutter build/reshutter moving.0001.mps static.0001.mps
#   (stores: reshutter generate -n 5000000 -o moving.0001.mps; add --motion 0 --knots 1 for static)
set -euo pipefail
rounds=4
if [[ ${1:-} == --rounds ]]; then rounds=$2; shift 2; fi
[[ $# -eq 4 ]] || { sed -n 2,9p "$0" >&2; exit 2; }
a=$1 b=$2 moving=$3 static=$4
work=$(mktemp -d /tmp/reshutter-frames.XXXXXX)
trap 'rm -rf "$work"' EXIT

source "$(dirname "$0")/host.sh"
host_line
for ((i = 1; i <= rounds; ++i)); do
  for run in full quarter instant motion-free; do
    case $run in
      full) store=$moving extra=() ;;
      quarter) store=$moving extra=(--shutter 0.25:0.5) ;;
      instant) store=$moving extra=(--shutter 0.5:0.5) ;;
      motion-free) store=$static extra=() ;;
    esac
    for side in A B; do
      bin=$a
      [[ $side == B ]] && bin=$b
      /usr/bin/time -o "$work/time" -f "%e %M" "$bin" -q resample "$store" --spp 16 --filter gaussian:2x2 "${extra[@]}" -o "$work/out.exr" >/dev/null
      echo "$run $side $(cat "$work/time")"
    done
  done
done | python3 -c '
import sys, collections
wall, rss = collections.defaultdict(list), collections.defaultdict(int)
order = []
for line in sys.stdin:
    run, side, w, m = line.split()
    key = (run, side)
    if key not in wall: order.append(key)
    wall[key].append(float(w)); rss[key] = max(rss[key], int(m))
for key in order:
    print(f"{key[0]:12s} {key[1]}  wall s " + " ".join(f"{w:.2f}" for w in sorted(wall[key])) + f"   peak RSS {rss[key] / 1024:.0f} MB")
'

#!/usr/bin/env bash
# Drives `iso view FILE.iso` in a window on a virtual display (run under xvfb-run): K three times
# (kept points as splats, both, then the kept points as image-space points), P for a screenshot,
# K once more (the surface again), P, and Escape. Each key waits for the window's title to show
# the frames before it (a key pressed during a long first frame would be taken with the next).
# With a fourth argument, `none`, the file keeps no points: after K three times the window says
# so and goes on with the surface; P, then Escape.
# Usage: mode_window_session.sh ISO_BINARY FILE.iso WORKDIR [none]
set -euo pipefail
iso=$1 file=$2 work=$3 kept=${4:-kept}
source "$(dirname "$0")/session_common.sh"
cd "$work"
# Wait (at most 60 s) until the window's title matches PATTERN.
wait_title() {
  for _ in $(seq 600); do
    xdotool getwindowname "$window" 2>/dev/null | grep -q -- "$1" && return 0
    sleep 0.1
  done
  echo "the window's title never showed '$1'" >&2
  return 1
}
open_window "$file" --width 240 --height 180
wait_title "Mrays/s"
xdotool windowfocus --sync "$window" 2>/dev/null || true
xdotool mousemove --window "$window" 120 90
for _ in 1 2 3; do
  xdotool key k                     # points, both, image-space points
  sleep 1
done
if [ "$kept" = none ]; then
  for _ in $(seq 600); do grep -q "keeps no points" err.txt && break; sleep 0.1; done
  wait_title "Mrays/s"
  xdotool key p                     # iso-screenshot-1.png: the surface
  sleep 1
  xdotool key Escape
  wait $pid
  exit
fi
wait_title "image-space points"
xdotool key p                       # iso-screenshot-1.png: image-space points
sleep 1
xdotool key k                       # the surface
wait_title "Mrays/s"
xdotool key p                       # iso-screenshot-2.png: the surface
sleep 1
xdotool key Escape
wait $pid

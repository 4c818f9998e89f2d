#!/usr/bin/env bash
# Drives `iso view SCAN --vram SMALL --camera CLOSE` (image-space points, more read than fit) in
# a window on a virtual display (run under xvfb-run): once all is read and the points of the
# close view are drawn, presses P for a screenshot, turns the wheel back seven notches (the
# camera backs off to 2.1 times its distance, however slow the frames), waits (at most 60 s) until
# the points of the view it rests at are drawn, presses P again, and closes it with Escape.
# Usage: refine_window_session.sh ISO_BINARY SCAN WORKDIR VRAM CAMERA
set -euo pipefail
iso=$1 file=$2 work=$3 vram=$4 camera=$5
source "$(dirname "$0")/session_common.sh"
cd "$work"
# Wait (at most 60 s) until out.txt holds COUNT lines of points chosen for a view.
wait_views() {
  for _ in $(seq 600); do
    [ "$(grep -c "chosen for the view" out.txt || true)" -ge "$1" ] && return 0
    sleep 0.1
  done
  echo "out.txt never held $1 views' points" >&2
  return 1
}
open_window "$file" --vram "$vram" --camera "$camera" --width 300 --height 200
wait_views 1
sleep 1
xdotool windowfocus --sync "$window" 2>/dev/null || true
xdotool mousemove --window "$window" 150 100
xdotool key p                       # iso-screenshot-1.png: the close view's points
sleep 1
xdotool click --repeat 7 --delay 100 5
wait_views 2
sleep 1
xdotool key p                       # iso-screenshot-2.png: the points of the view it rests at
sleep 1
xdotool key Escape
wait $pid

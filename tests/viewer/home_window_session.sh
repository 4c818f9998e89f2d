#!/usr/bin/env bash
# Drives `iso view` in a window on a virtual display (run under xvfb-run): a screenshot at the view
# it starts at (P), an orbit (a drag) and a screenshot there, then Home back to the start and
# Escape (final.png). Each step waits for the chunks to be resident and for the picture it asked
# for, not for a fixed time: a loaded machine draws slowly.
# Usage: home_window_session.sh ISO_BINARY FILE.iso WORKDIR
set -euo pipefail
iso=$1 file=$2 work=$3
source "$(dirname "$0")/session_common.sh"
cd "$work"
# Presses P until iso-screenshot-N.png is there (written whole or not at all; again every 3 s: a
# window still starting may miss the key), moving the pointer a pixel now and then (a window that waits for
# events wakes up).
shoot() {
  for i in $(seq 900); do
    [ -f "iso-screenshot-$1.png" ] && return 0
    if [ $((i % 30)) -eq 0 ]; then xdotool key p || true; fi
    if [ $((i % 5)) -eq 0 ]; then xdotool mousemove --window "$window" $((150 + i % 2)) 100 || true; fi
    sleep 0.1
  done
  echo "the window saved no picture $1" >&2
  return 1
}
# Waits until the window's title says every chunk asked for is resident.
settled() {
  for _ in $(seq 900); do
    xdotool getwindowname "$window" | grep -Eq 'chunks [1-9][0-9]* resident, 0 requested' && return 0
    sleep 0.1
  done
  echo "the window's chunks did not settle: $(xdotool getwindowname "$window")" >&2
  return 1
}
open_window "$file" --width 300 --height 200
sleep 1
xdotool mousemove --window "$window" 150 100
settled
shoot 1
xdotool mousedown 1
sleep 0.5
xdotool mousemove --window "$window" 260 60
sleep 0.5
xdotool mouseup 1
sleep 0.5
settled
shoot 2
xdotool key Home
sleep 1
settled
xdotool key Escape
wait $pid

#!/usr/bin/env bash
# Drives `iso view` in a window on a virtual display (run under xvfb-run): resizes the window,
# presses P for a screenshot, drags the mouse to orbit, turns the material red in the scene file
# the window watches, and closes it with Escape (--frames only bounds a session that hangs: a
# count of frames would end it early on a fast machine, late on a slow one).
# Usage: window_session.sh ISO_BINARY FILE.iso WORKDIR
set -euo pipefail
iso=$1 file=$2 work=$3
source "$(dirname "$0")/session_common.sh"
cd "$work"
echo '{"material": {"color": [0.7, 0.7, 0.7]}}' >scene.json
open_window "$file" --scene scene.json --width 300 --height 200
sleep 1
xdotool windowsize "$window" 480 260
sleep 1
xdotool mousemove --window "$window" 240 130
xdotool key p                       # screenshot: iso-screenshot-1.png, before the orbit
sleep 1
xdotool mousedown 1
sleep 0.5
xdotool mousemove --window "$window" 400 130
sleep 0.5
xdotool mouseup 1
sleep 1
echo '{"material": {"color": [0.8, 0.05, 0.05]}}' >scene.json.new
mv scene.json.new scene.json
# Until the window has reloaded it (a loaded machine may take a while), then a frame or two more.
# The pointer moves a pixel now and then: a window that waits for events wakes up.
# (Under xvfb the tracer's window may not see the file change for a long while: after 3 s it
# is asked to reload with R, which the image window's session does not need.)
for i in $(seq 300); do
  grep -q reloaded out.txt && break
  if [ $((i % 5)) -eq 0 ]; then xdotool mousemove --window "$window" $((200 + i % 2)) 100 || true; fi
  if [ "$i" -eq 30 ]; then xdotool key r || true; fi
  sleep 0.1
done
sleep 1
xdotool key Escape
wait $pid

#!/usr/bin/env bash
# Drives `iso view` in a window on a virtual display (run under xvfb-run): resizes the window,
# presses P for a screenshot, drags the mouse to orbit (P again while the button is down), turns
# the material red in the scene file the window watches, and closes it with Escape (--frames only
# bounds a session that hangs: a count of frames would end it early on a fast machine, late on a
# slow one).
# Usage: window_session.sh ISO_BINARY FILE.iso WORKDIR
set -euo pipefail
iso=$1 file=$2 work=$3
source "$(dirname "$0")/session_common.sh"
cd "$work"
echo '{"material": {"color": [0.7, 0.7, 0.7]}}' >scene.json
open_window "$file" --scene scene.json --width 300 --height 200
# Every step waits for what the window did (a loaded machine draws a frame in seconds, and takes
# the events since the last frame at once), never for a fixed time.
xdotool windowsize --sync "$window" 480 260
xdotool mousemove --window "$window" 240 130
xdotool key p                       # screenshot: iso-screenshot-1.png, before the orbit
wait_for_output "saved iso-screenshot-1.png" 120
# The orbit: the window reads the button's state once a frame, so the button stays down until a
# frame has seen it with the pointer moved: the frame that takes screenshot 2, whose key comes
# after the drag.
xdotool mousedown 1
xdotool mousemove --window "$window" 400 130
xdotool key p                       # screenshot: iso-screenshot-2.png, after the drag
wait_for_output "saved iso-screenshot-2.png" 120
xdotool mouseup 1
echo '{"material": {"color": [0.8, 0.05, 0.05]}}' >scene.json.new
mv scene.json.new scene.json
# Until the window has reloaded it, then a frame or two more (the last frame, final.png, is drawn
# after Escape in any case). The pointer moves a pixel now and then: a window that waits for
# events wakes up. (Under xvfb the tracer's window may not see the file change for a long while:
# after 3 s it is asked to reload with R, which the image window's session does not need.)
for i in $(seq 1200); do
  grep -q reloaded out.txt && break
  if [ $((i % 5)) -eq 0 ]; then xdotool mousemove --window "$window" $((200 + i % 2)) 100 || true; fi
  if [ "$i" -eq 30 ]; then xdotool key r || true; fi
  sleep 0.1
done
sleep 1
xdotool key Escape
wait $pid

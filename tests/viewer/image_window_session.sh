#!/usr/bin/env bash
# Drives `iso view SCAN` (image-space points) in a window on a virtual display (run under
# xvfb-run): presses M (eye-dome shading) and L (two layers), P for a screenshot, makes the scan
# half transparent in the scene file the window watches, and closes it with Escape.
# Usage: image_window_session.sh ISO_BINARY SCAN WORKDIR
set -euo pipefail
iso=$1 file=$2 work=$3
source "$(dirname "$0")/session_common.sh"
cd "$work"
echo '{"image": {"opacity": 1}}' >scene.json
open_window "$file" --scene scene.json --width 300 --height 200
sleep 2
xdotool windowfocus --sync "$window" 2>/dev/null || true
xdotool mousemove --window "$window" 150 100
xdotool key p                       # screenshot: iso-screenshot-1.png, lit, one layer
sleep 1
xdotool key m l                     # eye-dome shading, two layers
sleep 1
echo '{"image": {"opacity": 0.5}}' >scene.json.new
mv scene.json.new scene.json
# Until the window has reloaded it (a loaded machine may take a while), then a frame or two more.
# The pointer moves a pixel now and then: a window that waits for events wakes up.
for i in $(seq 300); do
  grep -q reloaded out.txt && break
  if [ $((i % 5)) -eq 0 ]; then xdotool mousemove --window "$window" $((200 + i % 2)) 100 || true; fi
  sleep 0.1
done
sleep 1
xdotool key Escape
wait $pid

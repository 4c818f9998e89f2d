#!/usr/bin/env bash
# Drives `iso view FILE --draw pss` (point set surfaces) in a window on a virtual display (run
# under xvfb-run): P for a screenshot, a drag that orbits the camera, X (exact mode) and 1
# (shadows off), then Escape.
# Usage: pss_window_session.sh ISO_BINARY FILE WORKDIR
set -euo pipefail
iso=$1 file=$2 work=$3
source "$(dirname "$0")/session_common.sh"
cd "$work"
open_window "$file" --draw pss --width 160 --height 120
# Until the first full picture is shown (the pipeline is made and the surface fitted first).
for _ in $(seq 600); do grep -q "first full picture" out.txt && break; sleep 0.1; done
sleep 0.5
xdotool windowfocus --sync "$window" 2>/dev/null || true
xdotool mousemove --window "$window" 80 60
xdotool key p                       # screenshot: iso-screenshot-1.png
sleep 1
xdotool mousedown --window "$window" 1
for x in 90 100 110 120 130; do xdotool mousemove --window "$window" $x 60; sleep 0.1; done
xdotool mouseup --window "$window" 1
sleep 2
xdotool key x 1                     # exact mode, shadows off
sleep 3
xdotool key Escape
wait $pid

# Sourced by the window sessions (window_session.sh, image_window_session.sh,
# mode_window_session.sh): `open_window
# ARGS...` starts `iso view ARGS... --frames 20000 --screenshot final.png` in the background
# (out.txt, err.txt), sets $pid and $window once its window appears, and fails when none does
# within a minute (a loaded machine may take a while to start a Vulkan device) or when `iso view`
# ends without one (after one more start when the display refused it).
# --frames only bounds a session that hangs: the session closes the window with Escape.
# `wait_for_output TEXT SECONDS` waits until the window has printed TEXT (a line of out.txt) and
# fails, closing the window, when it has not within SECONDS: the sessions wait for what the
# window did, not for a time that a slow machine may not keep.
open_window() {
  local attempt
  for attempt in 1 2; do
    "$iso" view "$@" --frames 20000 --screenshot final.png >out.txt 2>err.txt &
    pid=$!
    window=
    for _ in $(seq 600); do
      window=$(xdotool search --name "iso view" 2>/dev/null | head -1 || true)
      [ -n "$window" ] && return 0
      kill -0 $pid 2>/dev/null || break  # it ended without a window
      sleep 0.1
    done
    if kill -0 $pid 2>/dev/null; then kill $pid; break; fi
    # The virtual display refused the connection once in a loaded CI run (GLFW could not open it):
    # the window is started again once after that error alone; any other ends the session.
    grep -qF "cannot open a window" err.txt || break
    [ $attempt = 1 ] && { echo "iso view could not open the display; starting it again" >&2; sleep 1; }
  done
  echo "no window appeared" >&2
  exit 1
}

wait_for_output() {
  local text=$1 seconds=$2
  for _ in $(seq $((seconds * 10))); do
    grep -qF "$text" out.txt && return 0
    sleep 0.1
  done
  echo "the window did not print \"$text\" within $seconds s" >&2
  kill $pid
  exit 1
}

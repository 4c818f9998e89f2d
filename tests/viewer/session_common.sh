# Sourced by the window sessions (window_session.sh, image_window_session.sh,
# mode_window_session.sh): `open_window
# ARGS...` starts `iso view ARGS... --frames 20000 --screenshot final.png` in the background
# (out.txt, err.txt), sets $pid and $window once its window appears, and fails when none does.
# --frames only bounds a session that hangs: the session closes the window with Escape.
open_window() {
  "$iso" view "$@" --frames 20000 --screenshot final.png >out.txt 2>err.txt &
  pid=$!
  window=
  for _ in $(seq 100); do
    window=$(xdotool search --name "iso view" 2>/dev/null | head -1 || true)
    [ -n "$window" ] && break
    sleep 0.1
  done
  [ -n "$window" ] || { echo "no window appeared" >&2; kill $pid; exit 1; }
}

#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Run a command under a private virtual X server (Xvfb) and stop the server afterwards.
#   usage: scripts/xvfb.sh [-s "SERVER ARGS"] COMMAND [ARG...]      (default server args: -screen 0 1600x1000x24)
# The exit code is the command's. Why not `xvfb-run -a`: it picks the display number by looking for a free lock file
# and then starts Xvfb, so two runs that start together (ctest -j2) can pick the same number; the loser's Xvfb fails
# and its program dies with "bad X server connection" (CI, 2026-11-27: the batch test's report, twice in a row). Here
# Xvfb chooses the number itself (-displayfd: it takes the first display whose lock it can create) and tells us.
# -noreset: by default Xvfb resets when its last client disconnects, and a client that connects during the reset
# gets no display (XOpenDisplay returns NULL: VTK's "bad X server connection"). `aneuprep report` opens and closes a
# render window per picture, so it could hit that window (CI, 2026-11-28, alone at the end of the suite; pyvista
# found the same: 45-73 failures in 1200 connections with resets, 0 with -noreset, pyvista/pyvista#9188).
set -uo pipefail
server_args="-screen 0 1600x1000x24"
if [ "${1:-}" = "-s" ]; then
  server_args="$2"
  shift 2
fi
[ $# -gt 0 ] || { echo "xvfb.sh: error: no command given (usage: scripts/xvfb.sh [-s ARGS] COMMAND...)" >&2; exit 2; }
command -v Xvfb >/dev/null || { echo "xvfb.sh: error: Xvfb not found (scripts/install_deps.sh installs xvfb)" >&2; exit 1; }
dir=$(mktemp -d "${TMPDIR:-/tmp}/aneu-xvfb.XXXXXX")
# shellcheck disable=SC2086  # the server's arguments are words
Xvfb -displayfd 3 -nolisten tcp -noreset $server_args 3>"$dir/display" 2>"$dir/xvfb.log" &
xpid=$!
stop() { kill "$xpid" 2>/dev/null; wait "$xpid" 2>/dev/null; rm -rf "$dir"; }
trap stop EXIT
trap 'exit 143' TERM INT
for _ in $(seq 1 400); do  # up to 20 s: the number is written once the server accepts connections
  grep -q '^[0-9][0-9]*$' "$dir/display" 2>/dev/null && break
  if ! kill -0 "$xpid" 2>/dev/null; then
    echo "xvfb.sh: error: Xvfb did not start: $(tail -n 3 "$dir/xvfb.log" | tr '\n' ' ')" >&2
    exit 1
  fi
  sleep 0.05
done
grep -q '^[0-9][0-9]*$' "$dir/display" || { echo "xvfb.sh: error: Xvfb gave no display number within 20 s" >&2; exit 1; }
display=":$(head -n 1 "$dir/display")"
DISPLAY="$display" "$@"
rc=$?
if [ $rc -ne 0 ]; then  # say what the server saw (a program that lost its display says only "bad X server connection")
  alive=no
  kill -0 "$xpid" 2>/dev/null && alive=yes
  echo "xvfb.sh: the command exited with $rc on display $display (Xvfb still running: $alive); Xvfb's log: $(tail -n 5 "$dir/xvfb.log" | tr '\n' ' ')" >&2
fi
exit $rc

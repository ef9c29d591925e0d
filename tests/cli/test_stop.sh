#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# aneusim run stopped by SIGTERM (a batch system's time limit): it ends at the next tick with exit status 143
# (128 + 15), its report written for the time reached (stopped_at_s) and its log under its final name.
# usage: test_stop.sh ANEUSIM DIR   (DIR holds case.h5 and scene_long.json: a scene far too long to finish)
set -euo pipefail
sim=$1 dir=$2
cd "$dir"
rm -f long_log.csv long_report.json
"$sim" run scene_long.json --deterministic > long.out 2> long.err &
pid=$!
# Stop it once it is running (its bundle loaded), not after a fixed wait: on a fast machine this small tube runs
# 1000 simulated seconds in under 3 s, so the scene lasts 10^6 s and the signal goes as soon as the load is logged.
for _ in $(seq 1 300); do grep -q 'loaded ' long.err 2>/dev/null && break; sleep 0.1; done
sleep 0.5
kill -TERM $pid || { echo "aneusim ended before it was stopped"; cat long.err; exit 1; }
rc=0
wait $pid || rc=$?
[ "$rc" -eq 143 ] || { echo "exit status $rc, expected 143"; cat long.err; exit 1; }
grep -q '^stopped_at_s ' long.out || { echo "no stopped_at_s line"; cat long.out; exit 1; }
[ -f long_log.csv ] || { echo "no log under its final name"; ls; exit 1; }
python3 - <<'PY'
import json
r = json.load(open("long_report.json"))
t = r["stopped_at_s"]
assert 0 <= t < 1e6, t
assert abs(r["total_time_s"] - t) < 0.01 or t == 0, (r["total_time_s"], t)
print("stopped at t = %.4f s of 10^6 s, report written" % t)
PY
grep -q "stopped at t=" long.err || { echo "no warning saying where it stopped"; cat long.err; exit 1; }

#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# aneuview's frame rate on the sample case (issue #18): `aneusim serve` on the demo's planned scene (made live:
# keyframes dropped), aneuview under Xvfb steering the suction tube into the vessel (so every surface differs) for
# 300 surfaces (10 s at 30 Hz), at three window sizes, capped at 60 Hz (the default: a display shows no more) and
# uncapped (what the renderer can do). Server, viewer and Xvfb share the machine's cores.
# usage: bash bench/run_view_bench.sh [SCENE] [OUT.md]    (run `bash scripts/demo.sh` first)
#   ANEUVIEW=PATH runs another aneuview build (an A/B comparison on the same machine); SIZES="900,700 ..." the windows.
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-build/demo/sample/planned_scene.json}
out=${2:-bench/results/view.md}
w=$(mktemp -d)
trap 'rm -rf "$w"' EXIT
python3 - "$scene" "$w/live.json" <<'PY'
import json, os, sys
src, dst = sys.argv[1], sys.argv[2]
s = json.loads(''.join(l for l in open(src) if not l.lstrip().startswith('//')))
s['bundle'] = os.path.join(os.path.dirname(os.path.abspath(src)), s['bundle'])
s['live_input'] = True
s.pop('outputs', None)
for i in s['instruments']:
    i.pop('keyframes', None)
json.dump(s, open(dst, 'w'), indent=1)
PY
keys=$(printf 'i,%.0s' $(seq 12))
{
echo "# aneuview frame rate on the sample case (issue #18)"
echo
echo "\`bash bench/run_view_bench.sh\` ($(date -u +%F), $(nproc) cores, Xvfb with Mesa's llvmpipe software renderer; scene: $scene made live)."
echo "aneuview steers the suction tube 3 mm into the vessel (12 key presses) while \`aneusim serve\` streams 30 surfaces/s;"
echo "frame rate: every rendered frame from the viewer's start (window, connection, the server loading the bundle) to the 300th"
echo "surface; steady: from the first frame that showed a surface to the 300th (both rates end at the last frame rendered: the"
echo "screenshot written after it is not counted); render = time in Render(); interval = between the steady frames' ends; with"
echo "--max-fps 60, the periods of a 60 Hz display over the steady span that got no new frame (periods less frames)."
echo
echo "| window | --max-fps | surfaces | frames | frame rate (Hz) | steady (Hz) | render mean (ms) | interval p50 / p99 / max (ms) | display periods missed |"
echo "|---|---|---|---|---|---|---|---|---|"
} > "$out.tmp"
view=${ANEUVIEW:-build/tools/aneuview}
for size in ${SIZES:-600,500 900,700 1280,800}; do
    for fps in 60 0; do
        port=$(( 20000 + RANDOM % 20000 ))
        build/tools/aneusim serve "$w/live.json" --port $port --max-seconds 120 --idle-seconds 3 > "$w/serve.out" 2>&1 &
        server=$!
        bash scripts/xvfb.sh -s "-screen 0 1600x1000x24" "$view" --port $port --wait-seconds 60 --steer suction --keys "${keys%,}" \
            --screenshot "$w/view.png" --after-surfaces 300 --size $size --max-fps $fps > "$w/view.out"
        wait $server || true
        v() { awk -v k="$1" '$1 == k {print $2}' "$w/view.out"; }
        missed=$( [ "$fps" = 0 ] && echo "-" || echo "$(v display_periods_missed) of $(v display_periods)" )
        echo "| ${size/,/ x } | $fps | $(v surfaces_received) | $(v frames_rendered) | $(v frame_rate_hz) | $(v frame_rate_steady_hz) | $(v render_ms_mean) | $(v frame_interval_ms_p50) / $(v frame_interval_ms_p99) / $(v frame_interval_ms_max) | $missed |" | tee -a "$out.tmp"
    done
done
mv "$out.tmp" "$out"
echo "written $out"

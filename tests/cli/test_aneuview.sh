#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_aneuview.sh PREP SIM VIEW WORKDIR
# aneuview against a running `aneusim serve` (issue #18): a tube with a sac (tubewall -> tetmesh -> assemble ->
# condense), served live; aneuview under Xvfb takes a screenshot after 3 surfaces and says where 400 vertices
# land on it. The pixels there must show each vertex's label colour (artery red, aneurysm yellow; a vertex behind
# the front surface may show the other, so at least 80 % per label), and the background must be white away from
# the vessel. Then aneuview renders for 3 s and its frame rate is printed (a figure for the bench, not asserted).
# Then aneuview steers the suction tube from the keyboard (scripted keys: 20 x 0.25 mm into the view, from 3 mm
# in front of the vessel): the server's report must show a force. Last, it steers the clip applier: load a clip,
# dragged aside with the mouse, 2 mm in, close, release, back off and aside; the deposited clip's near end, projected with the pose the server
# sent, must show the clip's grey (not the vessel's red or yellow, not the tool's blue, not the background).
set -eu
prep=$1 sim=$2 view=$3 w=$4/aneuview
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$w" && mkdir -p "$w"
"$prep" tubewall -o "$w/wall.h5" --sac-radius-mm 2 --neck-radius-mm 1.3 --length-mm 10 --edge-mm 0.3 -q
"$prep" tetmesh "$w/wall.h5" -o "$w/vol.h5" -q
"$prep" assemble "$w/vol.h5" -o "$w/fem.h5" -q
"$prep" condense "$w/fem.h5" -o "$w/case.h5" -q
cat > "$w/scene.json" <<JSON
{"bundle": "case.h5", "live_input": true,
 "clip_models": {"straight": {"jaw_length_mm": 4.0, "jaw_width_mm": 1.2, "jaw_thickness_mm": 0.5, "max_opening_deg": 45}},
 "instruments": [{"name": "suction", "kind": "suction", "radius_mm": 0.75},
                 {"name": "applier", "kind": "clip_applier"}]}
JSON
port=$(( 20000 + RANDOM % 20000 ))
"$sim" serve "$w/scene.json" --port $port --max-seconds 120 --idle-seconds 10 --report "$w/report.json" > "$w/serve.out" 2> "$w/serve.err" &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
bash "$here/../../scripts/xvfb.sh" "$view" --port $port --screenshot "$w/view.png" --after-surfaces 3 --points "$w/points.txt" --size 600,500 > "$w/view.out"
python3 - "$w/view.png" "$w/points.txt" "$here" <<'PY'
import sys
sys.path.insert(0, sys.argv[3])
from png_pixels import read_png
png, pts = sys.argv[1], sys.argv[2]
W, H, pixel = read_png(png)
lines = open(pts).read().split('\n')
good, total = {0: 0, 1: 0}, {0: 0, 1: 0}
for l in lines[1:]:
    if not l.strip() or l.startswith('clip'): continue
    _, x, y, lab = l.split()[:4]
    x, y, lab = int(round(float(x))), int(round(float(y))), int(round(float(lab)))
    if not (0 <= x < W and 0 <= y < H): continue
    r, g, b = pixel(x, y)
    red = r > 60 and g < 0.6 * r and b < 0.6 * r
    yellow = r > 60 and g > 0.7 * r and b < 0.7 * g
    total[lab] += 1
    good[lab] += (yellow if lab == 1 else red)
corner = pixel(2, H - 3)
print('aneuview: %d x %d; artery %d/%d red, aneurysm %d/%d yellow; corner %s' % (W, H, good[0], total[0], good[1], total[1], corner))
assert total[0] > 50 and total[1] > 20, total
assert good[0] >= 0.8 * total[0], 'artery vertices not red where they land'
assert good[1] >= 0.8 * total[1], 'sac vertices not yellow where they land'
assert min(corner) > 240, 'background not white'
PY
# The frame rate while the server streams: render for 3 s (screenshot after the 90th surface).
bash "$here/../../scripts/xvfb.sh" "$view" --port $port --screenshot "$w/view2.png" --after-surfaces 90 --size 600,500 | tee "$w/view2.out"
echo "aneuview frame rate: $(grep frame_rate_hz "$w/view2.out")"
# The frame statistics are consistent (no speed is asserted): intervals ordered, and the 60 Hz display's periods over
# the steady span are the steady frames plus the periods that got none.
python3 - "$w/view2.out" <<'PY'
import sys
v = dict((l.split()[0], float(l.split()[1])) for l in open(sys.argv[1]) if len(l.split()) == 2)
for k in ('frame_interval_ms_p50', 'frame_interval_ms_p99', 'frame_interval_ms_max', 'display_periods', 'display_periods_missed'):
    assert k in v, 'aneuview did not report ' + k
assert 0 < v['frame_interval_ms_p50'] <= v['frame_interval_ms_p99'] <= v['frame_interval_ms_max'], v
assert 0 <= v['display_periods_missed'] < v['display_periods'] and v['display_periods'] < v['frames_rendered'] + v['display_periods_missed'], v
PY
# Stereo, side by side: both halves show the vessel, the same size (one eye each).
bash "$here/../../scripts/xvfb.sh" "$view" --port $port --stereo side-by-side --screenshot "$w/stereo.png" --after-surfaces 3 --size 800,400 > "$w/stereo.out"
python3 - "$w/stereo.png" "$here" <<'PY'
import sys
sys.path.insert(0, sys.argv[2])
from png_pixels import read_png
W, H, pixel = read_png(sys.argv[1])
cols = [sum(1 for y in range(60, H) if min(pixel(x, y)) < 200) for x in range(W)]  # not background (the HUD at the bottom aside)
left, right = sum(cols[:W // 2]), sum(cols[W // 2:])
print('stereo: vessel pixels left %d, right %d' % (left, right))
assert left > 2000 and right > 2000, 'both eyes see the vessel'
assert abs(left - right) < 0.25 * max(left, right), 'the two views are alike'
PY
# Steering: 20 presses of 'i' move the suction tube 5 mm along its axis, through the wall in front of it.
keys=$(printf 'i,%.0s' $(seq 20))
bash "$here/../../scripts/xvfb.sh" "$view" --port $port --steer suction --keys "${keys%,}" --screenshot "$w/steer.png" --after-surfaces 60 --size 600,500 > "$w/steer.out"
# The clip: l, a Shift+drag 70 pixels left (away from where the suction tube stays), 8 x i (2 mm in), 8 x c
# (40 deg to 0), r, 20 x k (5 mm back), 20 x Up (5 mm aside: the tool off the clip).
keys="l,drag:-70:0,$(printf 'i,%.0s' $(seq 8))$(printf 'c,%.0s' $(seq 8))r,$(printf 'k,%.0s' $(seq 20))$(printf 'Up,%.0s' $(seq 20))"
bash "$here/../../scripts/xvfb.sh" "$view" --port $port --steer applier --clip-model straight --keys "${keys%,}" --screenshot "$w/clip.png" --after-surfaces 10 \
    --points "$w/clip_points.txt" --size 600,500 > "$w/clip.out"
python3 - "$w/clip.png" "$w/clip_points.txt" "$here" <<'PY'
import sys
sys.path.insert(0, sys.argv[3])
from png_pixels import read_png
W, H, pixel = read_png(sys.argv[1])
clips = [l.split() for l in open(sys.argv[2]) if l.startswith('clip ')]
assert clips, 'the viewer received no clip pose'
_, name, along, x, y = clips[0][:5]
x, y = int(round(float(x))), int(round(float(y)))
assert 3 <= x < W - 3 and 3 <= y < H - 3, 'the clip is off the screen'
def grey(p):
    r, g, b = p
    return abs(r - g) < 25 and -10 <= b - r < 50 and max(p) < 245 and min(p) > 60
near = [pixel(x + dx, y + dy) for dx in (-2, 0, 2) for dy in (-2, 0, 2)]
n = sum(grey(p) for p in near)
print('aneuview clip: %s near end at (%d, %d): %d/9 grey pixels, centre %s' % (name, x, y, n, pixel(x, y)))
assert n >= 7, 'the clip is not drawn where its pose puts it'
# The drag moved the applier's tip with the pointer at its depth: its ends, projected, lie 70 pixels apart, leftwards.
pt = {l.split()[0]: (float(l.split()[3]), float(l.split()[4])) for l in open(sys.argv[2]) if l.startswith('drag_')}
ddx, ddy = pt['drag_to'][0] - pt['drag_from'][0], pt['drag_to'][1] - pt['drag_from'][1]
print('aneuview drag: the tip moved %.2f, %.2f pixels' % (ddx, ddy))
assert abs(ddx + 70) <= 1 and abs(ddy) <= 1, 'the Shift+drag did not move the instrument with the pointer'
PY
wait $server
trap - EXIT
python3 - "$w/report.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print('steered session: peak force %.4f N, %d poses, %d clients' % (r['peak_force_n'], r['igtl']['poses'], r['igtl']['clients_connected']))
assert r['igtl']['clients_connected'] == 5, r['igtl']
assert r['clips_used'] == 1, 'the applier loaded one clip'
assert r['igtl']['poses'] >= 20, 'the steered poses reached the server'
assert r['peak_force_n'] > 0.005, 'the suction tube steered into the wall was pushed back'
PY

#!/usr/bin/env bash
# README command 1: install dependencies, build, and run the main job on the
# bundled sample data (no Docker; the services it needs run as plain
# processes on ephemeral loopback ports and are stopped at the end).
# Outputs go to ./out (override with KINEMO_OUT).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
OUT=${KINEMO_OUT:-out}
mkdir -p "$OUT"
K="$BUILD_DIR/services/cli/kinemo"
DATA=tests/data
SPEECH="$DATA/speech/sense_and_sensibility_01_austen_64kb-0870.wav"

PIDS=()
cleanup() { for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
# wait_port FILE PID: waits (bounded) until a server we started writes its port.
wait_port() {
  for _ in $(seq 1 600); do
    [ -s "$1" ] && { cat "$1"; return 0; }
    kill -0 "$2" 2>/dev/null || { echo "server $2 exited before listening" >&2; return 1; }
    sleep 0.05
  done
  echo "timed out waiting for $1" >&2; return 1
}

echo "== 1. motion: the bundled clips (three skeletons), and the 120 fps CMU clip resampled to 30 fps"
bvh_summary() {  # one line per clip from `kinemo bvh info --json`
  for f in "$@"; do "$K" bvh info "$f" --json; done | python3 -c '
import json, sys
dec, text, i = json.JSONDecoder(), sys.stdin.read(), 0
print(f"  {\"clip\":<34} {\"skeleton\":<14} {\"joints\":>6} {\"frames\":>6} {\"fps\":>5} {\"seconds\":>7}")
while i < len(text):
    while i < len(text) and text[i].isspace(): i += 1
    if i >= len(text): break
    d, i = dec.raw_decode(text, i)
    name = d["file"].split("/")[-1]
    print(f"  {name:<34} {d[\"skeleton_family\"]:<14} {d[\"num_joints\"]:>6} {d[\"num_frames\"]:>6} {d[\"fps\"]:>5.0f} {d[\"duration_s\"]:>7.2f}")
'
}
"$K" bvh convert "$DATA/motion/131_01.bvh" "$OUT/131_01_30fps.bvh" --fps 30
bvh_summary "$DATA"/motion/*.bvh "$OUT/131_01_30fps.bvh"
echo "  (kinemo bvh info FILE prints a clip's whole hierarchy with the body region of each joint)"

echo; echo "== 2. speech → prosody: pitch, intensity, syllables, pitch accents"
"$K" audio info "$SPEECH"
"$K" prosody "$SPEECH" --json > "$OUT/prosody.json"
"$K" prosody "$SPEECH" --textgrid > "$OUT/prosody.TextGrid"
python3 - "$OUT/prosody.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(f"{len(d['frames'])} frames, {len(d['syllables'])} syllables, {len(d['pauses'])} pauses, {len(d['accents'])} pitch accents")
for a in d['accents']:
    print(f"  accent at {a['time_s']:.2f} s  strength {a['strength']:.2f}  PSI {a['psi']:.2f}")
PY

echo; echo "== 3. inference: the remapped CRF against the remapped HMM on a held-out recording"
# A paired corpus of real speech and real gesture capture (a *synthetic*
# pairing: no public corpus of speech with its motion could be bundled). Four
# recordings train the model; the fifth is held out and scored (Gesture
# Controllers Fig. 4: log-likelihood per step of the kinematics given the speech).
HELD_OUT="$DATA/speech/sense_and_sensibility_01_austen_64kb-0930.wav"
TRAIN_SPEECH=()
for f in "$DATA"/speech/*.wav; do [ "$f" = "$HELD_OUT" ] || TRAIN_SPEECH+=("$f"); done
rm -rf "$OUT/corpus" "$OUT/corpus_heldout"
GESTURES=("$DATA"/planner_controller/*.bvh "$DATA"/planner_gesture/*.bvh)
"$K" crf corpus --out "$OUT/corpus" --speech "${TRAIN_SPEECH[@]}" --gestures "${GESTURES[@]}" --renditions 3 --seed 1
"$K" crf corpus --out "$OUT/corpus_heldout" --speech "$HELD_OUT" --gestures "${GESTURES[@]}" --renditions 3 --seed 2 >/dev/null
"$K" crf train --corpus "$OUT/corpus" --states 8 --window 4 --seed 1 --out "$OUT/crf_model.kmodel" > /dev/null
"$K" crf evaluate --model "$OUT/crf_model.kmodel" --corpus "$OUT/corpus_heldout" --json | python3 -c '
import json, sys
d = json.load(sys.stdin)
print(f"  held-out recording, {d[\"steps\"]} steps: CRF {d[\"crf_ll_per_step\"]:.2f} vs remapped HMM {d[\"hmm_ll_per_step\"]:.2f} log-likelihood per step (higher is better)")
'

echo; echo "== 4. the AvatAR cube: render a lift-rotate-place sequence over a real photo, then track it"
"$K" cube net --model "$DATA/cube/vleo.cube" --out "$OUT/cube_net.png"
"$K" cube render --model "$DATA/cube/vleo.cube" --script "$DATA/cube/lift_rotate_place.json" \
  --out "$OUT/cube.avi" --truth "$OUT/cube_truth.json" --camera "$OUT/cube_camera.yml"
"$K" cube track "$OUT/cube.avi" --model "$DATA/cube/vleo.cube" --intrinsics "$OUT/cube_camera.yml" --json \
  > "$OUT/cube_track.jsonl"
python3 - "$OUT/cube_track.jsonl" <<'PY'
import json, sys
n, ramp = 0, None
def flush():
    global ramp
    if ramp:
        print(f"  t={ramp[0]:5.2f}-{ramp[1]:5.2f}s  intensity {ramp[2]:+.2f} -> {ramp[3]:+.2f} (the cube turned)")
    ramp = None
for line in open(sys.argv[1]):
    s = json.loads(line); n += 1
    for e in s.get('events', []):
        kind = e.get('type', '')
        if kind in ('lost', 'found'): continue
        if kind == 'intensity_changed':
            ramp = [ramp[0], e['time_s'], ramp[2], e['intensity']] if ramp else [e['time_s'], e['time_s'], e['previous_intensity'], e['intensity']]
            continue
        flush()
        print(f"  t={e['time_s']:5.2f}s  {kind.replace('_', ' ')}: {e['action']} on top (face {e['top_face']})")
flush()
print(f"  {n} frames tracked")
PY

echo; echo "== 5. robot: a simulated Pleo (Modbus TCP) driven through robot_bridge"
RUN=$(mktemp -d)
"$BUILD_DIR/services/pleo_sim/pleo_sim" --tcp 127.0.0.1:0 --port-file "$RUN/pleo.port" > "$RUN/pleo.log" 2>&1 &
PIDS+=($!)
PLEO_PORT=$(wait_port "$RUN/pleo.port" "${PIDS[-1]}")
printf 'server { host: "127.0.0.1" port: 0 log_level: "warn" }\nrobots { robot_id: "pleo" tcp { host: "127.0.0.1" port: %s } }\n' \
  "$PLEO_PORT" > "$RUN/bridge.textproto"
"$BUILD_DIR/services/robot_bridge/robot_bridge" --config "$RUN/bridge.textproto" --port-file "$RUN/bridge.port" \
  > "$RUN/bridge.log" 2>&1 &
PIDS+=($!)
BRIDGE="127.0.0.1:$(wait_port "$RUN/bridge.port" "${PIDS[-1]}")"
for emotion in happy angry neutral; do
  "$K" robot set pleo "$emotion" --intensity 0.8 --wait --bridge "$BRIDGE" --timeout-s 5
done
"$K" robot status pleo --bridge "$BRIDGE"
cleanup; PIDS=()
rm -rf "$RUN"

echo; echo "== 6. speech → animation: the all-in-one stack (every service in one process) animates the speech"
# No stack is running here, so `kinemo animate` starts kinemo_allinone on an
# ephemeral port with the bundled gesture library (BodySpeech), and stops it.
"$K" animate "$SPEECH" -o "$OUT/animate.bvh" --visemes "$OUT/visemes.json" --summary "$OUT/animate_summary.json"
"$K" preview "$OUT/animate.bvh" -o "$OUT/animate.png" --panels 12
python3 - "$OUT/visemes.json" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))
print(f"visemes: {len(v['categories'])} categories x {len(v['frames'])} frames at {1 / v['frame_time_s']:.0f} fps")
PY

echo; echo "== 7. Vleo → Pleo: a rendered cube video drives a session; pleo_sim follows its emotion"
"$K" demo vleo --out "$OUT/vleo"

echo; echo "demo outputs in $OUT/ (animate.bvh, animate.png, visemes.json, prosody.TextGrid, cube.avi, vleo/ ...)"

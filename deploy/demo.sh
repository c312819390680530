#!/usr/bin/env bash
# README command 1: install dependencies, build, and run the main job on the
# bundled sample data (no Docker; the services it needs run as plain
# processes on ephemeral loopback ports and are stopped at the end).
# Outputs go to ./out (override with KINEMO_OUT).
# Prints `phase <name> <seconds> s` after each phase (install, configure and
# build from deploy/build.sh, then one per step) and `phase total`.
set -euo pipefail
cd "$(dirname "$0")/.."
source deploy/lib/phase.sh
demo_t0=$(phase_now)
bash deploy/build.sh --demo
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

phase motion
echo "== 1. motion: the bundled clips (four skeletons: Bandai, CMU iClone, CMU 31, SMPL-X), and the 120 fps CMU clip resampled to 30 fps"
bvh_summary() {  # one line per clip from `kinemo bvh info --json`
  local infos=()
  for f in "$@"; do "$K" bvh info "$f" --json >"$OUT/info_$(basename "$f").json"; infos+=("$OUT/info_$(basename "$f").json"); done
  python3 - "${infos[@]}" <<'PY'
import json, sys
print(f"  {'clip':<34} {'skeleton':<14} {'joints':>6} {'frames':>6} {'fps':>5} {'seconds':>7}")
for path in sys.argv[1:]:
    d = json.load(open(path))
    name = d["file"].split("/")[-1]
    print(f"  {name:<34} {d['skeleton_family']:<14} {d['num_joints']:>6} {d['num_frames']:>6} {d['fps']:>5.0f} {d['duration_s']:>7.2f}")
PY
  rm -f "${infos[@]}"
}
"$K" bvh convert "$DATA/motion/131_01.bvh" -o "$OUT/131_01_30fps.bvh" --fps 30
bvh_summary "$DATA"/motion/*.bvh "$DATA"/paired/beat2/*.bvh "$OUT/131_01_30fps.bvh"
echo "  (kinemo bvh info FILE prints a clip's whole hierarchy with the body region of each joint)"

phase prosody
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

phase inference
echo; echo "== 3. inference: the remapped CRF on speech and motion recorded together (BEAT2), each take held out in turn"
# Two takes of one speaker talking freely, the motion captured with the
# speech (tests/data/paired/beat2). Each fold trains on one take and scores the
# other: log-likelihood per step of the kinematics given the speech
# (Gesture Controllers Fig. 4), CRF against the remapped HMM.
"$K" crf fig4 --paired "$DATA/paired/beat2" --states 8 --json >"$OUT/crf_heldout.json"
python3 - "$OUT/crf_heldout.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
for f in d['folds']:
    print(f"  trained on {', '.join(f['train'])}, held out {f['test']} ({f['steps']} steps): "
          f"CRF {f['crf_ll_per_step']:.2f} vs remapped HMM {f['hmm_ll_per_step']:.2f} log-likelihood per step (higher is better)")
PY

phase cube
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
        t0, t1, first, last, lo, hi = ramp
        print(f"  t={t0:5.2f}-{t1:5.2f}s  the cube turned: intensity {first:+.2f} -> {last:+.2f} (range {lo:+.2f}..{hi:+.2f})")
    ramp = None
for line in open(sys.argv[1]):
    s = json.loads(line); n += 1
    for e in s.get('events', []):
        kind = e.get('type', '')
        if kind in ('lost', 'found'): continue
        if kind == 'intensity_changed':
            v = e['intensity']
            if ramp:
                ramp = [ramp[0], e['time_s'], ramp[2], v, min(ramp[4], v), max(ramp[5], v)]
            else:
                p = e['previous_intensity']
                ramp = [e['time_s'], e['time_s'], p, v, min(p, v), max(p, v)]
            continue
        flush()
        print(f"  t={e['time_s']:5.2f}s  {kind.replace('_', ' ')}: {e['action']} on top (face {e['top_face']})")
flush()
print(f"  {n} frames tracked")
PY

phase robot
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

phase animate
echo; echo "== 6. speech → animation: the all-in-one stack (every service in one process) animates the speech"
# No stack is running here, so each `kinemo animate` starts kinemo_allinone on
# an ephemeral port and stops it. Its artifact store ($KINEMO_STORE_DIR, else
# ~/.local/share/kinemo/store) is seeded from the bundled store the build made:
# the Gesture Controller "bundled" (model + controller) and the BodySpeech
# graph "bundled" over the bundled gesture library.
echo "-- Gesture Controller (prosody -> remapped CRF beliefs -> MDP policy), bundled model and controller"
"$K" animate "$SPEECH" --method gc -o "$OUT/animate_gc.bvh"
echo "-- BodySpeech (gesture phrases on the pitch accents) with visemes"
"$K" animate "$SPEECH" --method bodyspeech -o "$OUT/animate.bvh" --visemes "$OUT/visemes.json" --summary "$OUT/animate_summary.json"
"$K" preview "$OUT/animate.bvh" -o "$OUT/animate.png" --panels 12
python3 - "$OUT/visemes.json" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))
print(f"visemes: {len(v['categories'])} categories x {len(v['frames'])} frames at {1 / v['frame_time_s']:.0f} fps")
PY
echo "-- live: the speech streamed in 20 ms chunks at real-time pace through StreamAnimate"
"$K" animate "$SPEECH" --stream --realtime -o "$OUT/animate_live.bvh" --json >"$OUT/animate_live.json"
python3 - "$OUT/animate_live.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(f"{d['frames']} frames for {d['audio_s']:.2f} s of audio; audio sent -> frame received: "
      f"p50 {d['motion_lag_p50_ms']:.1f} ms, p99 {d['motion_lag_p99_ms']:.1f} ms; "
      f"first frame {d['first_frame_ms']:.1f} ms after the first chunk; longest gap between frames {d['max_frame_gap_ms']:.0f} ms")
PY
echo "-- feet: slide while standing and floating, per output (targets: slide p95 <= 0.01 m/s, float <= 0.02 m)"
"$K" motion check "$OUT/animate_gc.bvh" "$OUT/animate.bvh" "$OUT/animate_live.bvh" --meters-per-unit 0.01 --json \
  >"$OUT/motion_check.json"
python3 - "$OUT/motion_check.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
for r in (d if isinstance(d, list) else [d]):
    print(f"  {r['file'].split('/')[-1]:<22} foot slide p95 {r['foot_slide_p95_m_s']:.4f} m/s, "
          f"float {r['max_float_m']:.3f} m, lowest sole {r['min_foot_height_m']:+.3f} m, hips drift {r['hips_drift_m']:.3f} m")
PY

phase vleo
echo; echo "== 7. Vleo → Pleo: a rendered cube video drives a session; pleo_sim follows its emotion"
"$K" demo vleo --out "$OUT/vleo"
phase_end
phase_since total "$demo_t0"

echo; echo "demo outputs in $OUT/ (animate.bvh, animate.png, visemes.json, prosody.TextGrid, cube.avi, vleo/ ...)"

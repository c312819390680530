#!/usr/bin/env bash
# Builds the bundled artifact store (docs/store.md) from bundled data only:
#   "bundled"  the conversational default — gesture library, BodySpeech/GMG
#              gesture graph, inference model (remapped CRF) and Gesture
#              Controller, all from BEAT2's two takes of one speaker talking
#              freely, speech and motion recorded together
#              (tests/data/paired/beat2, SMPL-X joint tree, 55 joints), with
#              tones estimated from styled capture (tests/data/tones);
#              and the face model (jaw and mouth shapes, docs/face.md);
#   "bandai"   the emblems (bow, bye, call, guide, respond, wave: Bandai-Namco
#              clips, 22 joints) as a named library with its graph, and a
#              model trained on a *synthetic* pairing of five LibriVox
#              recordings with those clips (not recorded together).
# It runs the very path a user takes: kinemo_allinone on an ephemeral
# loopback port, `kinemo crf train --server` and `kinemo controller build
# --server`. Fixed seeds make it deterministic; the build runs it again only
# when its inputs change (services/allinone/CMakeLists.txt).
#
#   deploy/seed-store.sh BUILD_DIR OUT_DIR
#
# OUT_DIR is replaced as a whole at the end. Services and the all-in-one use it
# as their seed_store_dir: its artifacts are copied into a store_dir that lacks
# them (the runtime image has it at /usr/local/share/kinemo/store).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="$(realpath "${1:?usage: seed-store.sh BUILD_DIR OUT_DIR}")"
out="${2:?usage: seed-store.sh BUILD_DIR OUT_DIR}"
out="$(realpath -m "$out")"
kinemo="$build/services/cli/kinemo"
allinone="$build/services/allinone/kinemo_allinone"
data="$root/tests/data"

work="$(mktemp -d)"
pid=""
cleanup() {
  if [[ -n "$pid" ]]; then kill -TERM "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; fi
  rm -rf "$work"
}
trap cleanup EXIT

staging="$out.partial"
rm -rf "$staging"
mkdir -p "$staging"
cat >"$work/allinone.textproto" <<EOF
server { host: "127.0.0.1" port: 0 log_level: "warn" shutdown_grace_s: 1 }
store_dir: "$staging"
seed_store_dir: "$work/no-seed"
planner {
  library_root: "$data"
  preload { library_id: "bundled" paths: "paired/beat2" }
  preload { library_id: "bandai" paths: "planner_gesture" paths: "planner_controller" }
  preload_gesture_graphs { graph_id: "bundled" library_id: "bundled" params { stroke_phrases: true } }
  preload_gesture_graphs { graph_id: "bandai" library_id: "bandai" params { stroke_phrases: true } }
}
EOF
"$allinone" --config "$work/allinone.textproto" --port-file "$work/port" >"$work/allinone.log" 2>&1 &
pid=$!
for _ in $(seq 1 600); do
  [[ -s "$work/port" ]] && break
  kill -0 "$pid" 2>/dev/null || { echo "seed-store: kinemo_allinone exited:" >&2; tail -5 "$work/allinone.log" >&2; exit 1; }
  sleep 0.05
done
[[ -s "$work/port" ]] || { echo "seed-store: kinemo_allinone did not start" >&2; exit 1; }
server="127.0.0.1:$(cat "$work/port")"

# The conversational default: a CRF trained on the real pairs.
"$kinemo" crf train --corpus "$data/paired/beat2" --states "${KINEMO_SEED_STATES:-8}" --window 4 --seed 1 \
  --server "$server" --id bundled \
  --description "bundled: BEAT2 speaker 2, two takes of free speech with the motion recorded together (124 s), ${KINEMO_SEED_STATES:-8} states, window 4" \
  >/dev/null 2>"$work/train.log" || { cat "$work/train.log" >&2; exit 1; }
# Its tones (neutral, angry, happy, energetic, subdued) come from styled
# capture: Bandai's angry/happy/active/sad takes vs its normal takes of the
# same actions (tests/data/tones), applied to the BEAT2 library.
"$kinemo" controller build --server "$server" --library-id bundled --model-id bundled --id bundled \
  --tones-from "$data/tones" >/dev/null 2>"$work/build.log" || { cat "$work/build.log" >&2; exit 1; }
# The emblems: a synthetic pairing of real speech with the Bandai clips.
"$kinemo" crf corpus --out "$work/corpus" --speech "$data"/speech/*.wav \
  --gestures "$data"/planner_controller/*.bvh "$data"/planner_gesture/*.bvh --renditions 3 --seed 1 >/dev/null
"$kinemo" crf train --corpus "$work/corpus" --states 8 --window 4 --seed 1 --server "$server" --id bandai \
  --description "bandai: 5 LibriVox recordings x 3 renditions of the bundled Bandai gestures (synthetic pairing), 8 states, window 4" \
  >/dev/null 2>"$work/train.log" || { cat "$work/train.log" >&2; exit 1; }
"$kinemo" controller build --server "$server" --library-id bandai --model-id bandai --id bandai \
  >/dev/null 2>"$work/build.log" || { cat "$work/build.log" >&2; exit 1; }
"$kinemo" artifacts ls --server "$server" >"$work/ls.txt"

kill -TERM "$pid"
wait "$pid" || true
pid=""
# The face model (the prosody service's face_models): jaw and mouth shapes
# learned from the same two takes (their SMPL-X jaw is the captured face,
# their TextGrids the phones); written once the stack has stopped (a store
# folder has one writer at a time).
"$kinemo" face train --corpus "$data/paired/beat2" --store "$staging" --id bundled \
  --description "bundled: BEAT2 speaker 2, two takes (124 s): jaw from the captured SMPL-X jaw, mouth shapes from the TextGrid phones" \
  >/dev/null 2>"$work/face.log" || { cat "$work/face.log" >&2; exit 1; }
rm -rf "$staging/.staging" "$out"
mv "$staging" "$out"
echo "seed-store: $(grep -c . "$work/ls.txt") artifacts in $out"

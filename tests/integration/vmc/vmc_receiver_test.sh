#!/usr/bin/env bash
# `kinemo animate --stream --realtime --vmc 127.0.0.1:PORT` on bundled speech
# (the embedded kinemo_allinone, the bundled library), received by an
# independent VMC receiver (tests/tools/vmc_receiver: Node and npm's `osc`,
# which the project uses nowhere else): every frame's bones, the wrist path
# by the receiver's own forward kinematics against kinemo's BVH of the same
# run (within 1 cm), bone messages per second, the face's blend shapes; once
# with Unity bone names, once with VRM 1.0 names. The receiver listens on a
# port the system picks and says so on a line ("ready PORT"); no sleeps.
#   vmc_receiver_test.sh SOURCE_DIR BUILD_DIR [FACE]   (FACE: required|absent|auto)
set -euo pipefail
src="$1" build="$2" face="${3:-auto}"
kinemo="$build/services/cli/kinemo"
tool="$src/tests/tools/vmc_receiver"
work="$(mktemp -d)"
receiver_pid=""
cleanup() {
  local rc=$?
  if [[ -n "$receiver_pid" ]]; then kill -TERM "$receiver_pid" 2>/dev/null || true; wait "$receiver_pid" 2>/dev/null || true; fi
  rm -rf "$work"
  exit $rc
}
trap cleanup EXIT

command -v node >/dev/null || { echo "SKIP: node is not installed (deploy/install-deps.sh --all)"; exit 77; }
# npm's osc, from the committed lock: installed by deploy/install-deps.sh
# --all into the tool's folder; else installed here into a copy.
if [[ ! -d "$tool/node_modules/osc" ]]; then
  cp "$tool/package.json" "$tool/package-lock.json" "$tool/receiver.mjs" "$tool/check.mjs" "$work/"
  tool="$work"
  (cd "$tool" && npm ci --omit=optional --no-audit --no-fund --loglevel=error >npm.log 2>&1) || {
    echo "SKIP: npm ci of the VMC receiver failed (registry unreachable?)"; tail -5 "$tool/npm.log"; exit 77; }
fi

# One run: WAV, bone names -> kinemo's JSON line and the check's.
run() {
  local wav="$1" bones="$2" name="$3"
  mkfifo "$work/$name.ready"
  node "$tool/receiver.mjs" --out "$work/$name.rec.json" >"$work/$name.ready" 2>"$work/$name.receiver.err" &
  receiver_pid=$!
  exec 3<"$work/$name.ready"
  local line=""
  read -r -t 30 -u 3 line || { echo "FAIL: the receiver did not say it was ready"; cat "$work/$name.receiver.err"; exit 1; }
  local port="${line#ready }"
  [[ "$line" == "ready "* && "$port" =~ ^[0-9]+$ ]] || { echo "FAIL: receiver said '$line'"; exit 1; }
  "$kinemo" animate "$wav" --stream --realtime --embedded --vmc "127.0.0.1:$port" --vmc-bones "$bones" \
    -o "$work/$name.bvh" --visemes "$work/$name.visemes.json" --json >"$work/$name.kinemo.json" 2>"$work/$name.kinemo.err" ||
    { echo "FAIL: kinemo animate --vmc"; cat "$work/$name.kinemo.err"; exit 1; }
  kill -TERM "$receiver_pid"
  wait "$receiver_pid"
  receiver_pid=""
  exec 3<&-
  echo "kinemo, $name: $(cat "$work/$name.kinemo.json")"
  echo -n "receiver, $name: "
  node "$tool/check.mjs" --recording "$work/$name.rec.json" --bvh "$work/$name.bvh" \
    --kinemo "$work/$name.kinemo.json" --bones "$bones" --face "$face" --visemes "$work/$name.visemes.json"
}

speech="$src/tests/data/speech/sense_and_sensibility_01_austen_64kb"
run "$speech-0870.wav" unity unity
run "$speech-0880.wav" vrm1 vrm1
echo "PASS"

#!/usr/bin/env bash
# Starts the whole topology — as processes on loopback (`local`) or as
# containers under podman (`compose`) — on free ports, checks that every
# service serves and that a command crosses robot_bridge -> Modbus -> pleo_sim
# (and, with a coordinator, that a session's actions reach the robot) and
# that every service answers GET /metrics, then
# stops exactly what it started. With `tls`, the stack runs with mutual TLS
# (KINEMO_TLS=1): every command below presents the CLI's certificate, and
# clients without one, with one from another CA or with an expired one are
# refused first.
#   stack_test.sh local|compose SOURCE_DIR BUILD_DIR [tls]
set -euo pipefail
mode="$1" src="$2" build="$3" tls="${4:-}"
kinemo="$build/services/cli/kinemo"
health="$build/services/cli/kinemo-health"
work="$(mktemp -d)"
unset KINEMO_TLS_CA KINEMO_TLS_CERT KINEMO_TLS_KEY
if [[ "$tls" == tls ]]; then
  export KINEMO_TLS=1 KINEMO_TLS_DIR="$work/certs" KINEMO_TLS_MOUNT="$work/compose-certs"
  bash "$src/deploy/certs.sh" --test-extras "$KINEMO_TLS_DIR" >/dev/null  # the stack keeps them
fi

source "$src/tests/integration/free_ports.sh"
# Every port of the stack, distinct: the service ports and, but for pleo_sim,
# their /metrics ports (deploy/config).
stack_ports() {
  local vars=()
  for s in PLEO_SIM ROBOT_BRIDGE PROSODY INFERENCE PLANNER CUBE_TRACKER COORDINATOR STUDIO; do
    vars+=("KINEMO_PORT_$s")
    [[ $s == PLEO_SIM ]] || vars+=("KINEMO_METRICS_PORT_$s")
  done
  export_free_ports "${vars[@]}"
}

cleanup() {
  local rc=$?
  if [[ "$mode" == local ]]; then
    KINEMO_STACK_DIR="$work/stack" bash "$src/deploy/local-stack.sh" down >/dev/null 2>&1 || true
  else
    bash "$src/deploy/compose.sh" down >/dev/null 2>&1 || true
    [[ -n "${KINEMO_TEST_IMAGE:-}" ]] || podman rmi -f "$KINEMO_IMAGE" >/dev/null 2>&1 || true
  fi
  rm -rf "$work"
  exit $rc
}

if [[ "$mode" == compose ]]; then
  source "$src/deploy/container/podman-env.sh"
  kinemo_podman_test_ready compose
  export KINEMO_COMPOSE_PROJECT="kinemotest$$"
  if [[ -n "${KINEMO_TEST_IMAGE:-}" ]]; then
    # ctest's fixture built it (podman_image.sh) and removes it.
    export KINEMO_IMAGE="$KINEMO_TEST_IMAGE" KINEMO_REBUILD_IMAGE=0
  else
    export KINEMO_IMAGE="localhost/kinemo/runtime:test$$" KINEMO_REBUILD_IMAGE=1
  fi
  export KINEMO_LIBRARY_DIR="$work/library" KINEMO_MEDIA_DIR="$work/media"
  export KINEMO_STUDIO_SECRETS="$work/studio-secrets"
  mkdir -p "$work/library" "$work/media"
  stack_ports
  trap cleanup EXIT
  bash "$src/deploy/compose.sh" up "$build"
  bridge="127.0.0.1:$KINEMO_PORT_ROBOT_BRIDGE"
  coordinator="127.0.0.1:$KINEMO_PORT_COORDINATOR"
else
  trap cleanup EXIT
  # The launcher uses the compose ports; the test runs on free ones.
  export KINEMO_STACK_DIR="$work/stack"
  stack_ports
  # The user's own configuration for one service (the others from
  # deploy/config): a coordinator whose default method is the Gesture Controller.
  mkdir -p "$work/userconf"
  cat >"$work/userconf/coordinator.textproto" <<EOF
server { host: "127.0.0.1" port: $KINEMO_PORT_COORDINATOR }
services {
  prosody { address: "127.0.0.1:$KINEMO_PORT_PROSODY" }
  inference { address: "127.0.0.1:$KINEMO_PORT_INFERENCE" }
  planner { address: "127.0.0.1:$KINEMO_PORT_PLANNER" deadline_s: 10 }
  cube_tracker { address: "127.0.0.1:$KINEMO_PORT_CUBE_TRACKER" }
  robot_bridge { address: "127.0.0.1:$KINEMO_PORT_ROBOT_BRIDGE" deadline_s: 1 max_reconnect_backoff_s: 0.5 }
}
animate {
  default_method: METHOD_GESTURE_CONTROLLER
  models { inference_model_id: "bundled" controller_id: "bundled" gesture_graph_id: "bundled" }
}
EOF
  bash "$src/deploy/local-stack.sh" up "$build" --config "$work/userconf"
  bridge="127.0.0.1:$KINEMO_PORT_ROBOT_BRIDGE"
  coordinator="127.0.0.1:$KINEMO_PORT_COORDINATOR"
fi

if [[ "$tls" == tls ]]; then
  c="$KINEMO_TLS_DIR"
  # Strangers are refused by every service, the coordinator and the bridge
  # included: at once (--fail-fast gives up at the failed handshake), not by
  # running out of time (each such check waited its whole --timeout before).
  refused() {  # refused TARGET WHO HEALTH-ARGS...
    local target="$1" who="$2" out
    shift 2
    if out="$("$health" "$target" --fail-fast --timeout-s 10 "$@" 2>&1)"; then
      echo "FAIL: $who reached $target"; exit 1
    fi
    if grep -qi "deadline" <<<"$out"; then
      echo "FAIL: $who got no answer from $target within 10 s, not a refusal: $out"; exit 1
    fi
    echo "$who refused by $target: ${out:0:200}"
  }
  for target in "$bridge" "$coordinator"; do
    refused "$target" "a plaintext client"
    refused "$target" "a client without a certificate" --ca "$c/ca.pem"
    refused "$target" "a certificate from another CA" --ca "$c/ca.pem" --cert "$c/stranger.pem" --key "$c/stranger.key"
    refused "$target" "an expired certificate" --ca "$c/ca.pem" --cert "$c/expired.pem" --key "$c/expired.key"
  done
  if "$kinemo" session list --coordinator "$coordinator" 2>"$work/refused.txt"; then echo "FAIL: kinemo without TLS options was served"; exit 1; fi
  cat "$work/refused.txt"
  # From here on every command presents the CLI's certificate (the environment).
  export KINEMO_TLS_CA="$c/ca.pem" KINEMO_TLS_CERT="$c/cli.pem" KINEMO_TLS_KEY="$c/cli.key"
  echo "strangers refused; the CLI's certificate accepted from here on"
fi

# Every service answers Prometheus' GET /metrics on its metrics port (with
# TLS: HTTPS to Prometheus' client certificate only, deploy/config/tls; the
# local run's coordinator uses the user's file, which has no metrics).
for s in ROBOT_BRIDGE PROSODY INFERENCE PLANNER CUBE_TRACKER COORDINATOR; do
  [[ "$mode" == local && $s == COORDINATOR ]] && continue
  var="KINEMO_METRICS_PORT_$s"
  if [[ "$tls" == tls ]]; then
    if curl -sf --max-time 5 "http://127.0.0.1:${!var}/metrics" >/dev/null 2>&1 ||
       curl -sf --max-time 5 --cacert "$c/ca.pem" "https://127.0.0.1:${!var}/metrics" >/dev/null 2>&1; then
      echo "FAIL: $s serves /metrics without Prometheus' client certificate"; exit 1; fi
    curl -sf --max-time 5 --cacert "$c/ca.pem" --cert "$c/prometheus.pem" --key "$c/prometheus.key" \
      "https://127.0.0.1:${!var}/metrics" | grep '^kinemo_rpc_started_total{' >/dev/null || {
      echo "FAIL: $s serves no /metrics over HTTPS on port ${!var}"; exit 1; }
  else
    curl -sf --max-time 5 "http://127.0.0.1:${!var}/metrics" | grep '^kinemo_rpc_started_total{' >/dev/null || {
      echo "FAIL: $s serves no /metrics on port ${!var}"; exit 1; }
  fi
done
# (No quote character inside ${tls:+...}: bash reads a ' there as the start
# of a quoted string, which swallowed the next 35 lines of this script.)
echo "every service serves /metrics${tls:+ over HTTPS, to the Prometheus client certificate only}"

# A command through the bridge reaches the simulated robot and is read back.
"$kinemo" robot set pleo happy --wait --bridge "$bridge"
status="$("$kinemo" robot status pleo --bridge "$bridge")"
echo "$status"
grep -q "shows happy" <<<"$status" || { echo "FAIL: the robot does not show happy"; exit 1; }
"$kinemo" robot set pleo angry --wait --bridge "$bridge"
"$kinemo" robot status pleo --bridge "$bridge" | grep -q "shows angry" || { echo "FAIL: the robot does not show angry"; exit 1; }

# The coordinator relays a Vleo's actions to the robot: an angry Pleo that
# gets kisses turns neutral (about 5 s at full intensity with the default
# emotion model).
"$kinemo" session open pleo --id stacktest --initial angry --coordinator "$coordinator"
"$kinemo" robot status pleo --bridge "$bridge" | grep -q "shows angry" || { echo "FAIL: the session did not set angry"; exit 1; }
"$kinemo" session act stacktest kisses -i 1 --coordinator "$coordinator"
deadline=$((SECONDS + 30))
until "$kinemo" robot status pleo --bridge "$bridge" | grep -q "shows neutral"; do
  (( SECONDS < deadline )) || { echo "FAIL: Pleo did not turn neutral within 30 s of kisses"; "$kinemo" session get stacktest --coordinator "$coordinator"; exit 1; }
  sleep 0.5
done
"$kinemo" session close stacktest --coordinator "$coordinator"

# Speech -> animation across prosody and planner (BodySpeech on the bundled graph).
"$kinemo" animate "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" \
  -o "$work/out.bvh" --coordinator "$coordinator"
"$kinemo" bvh info "$work/out.bvh" | grep "^frames:" >/dev/null || { echo "FAIL: no BVH from animate"; exit 1; }
# The Gesture Controller out of the box: the bundled model and controller,
# imported from the bundled seed store.
"$kinemo" animate "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" \
  -o "$work/gc.bvh" --coordinator "$coordinator" --method gc
"$kinemo" bvh info "$work/gc.bvh" | grep "^frames:" >/dev/null || { echo "FAIL: no BVH from animate --method gc"; exit 1; }
if [[ "$mode" == local ]]; then
  # The coordinator runs the user's configuration: its default method is GC.
  summary="$("$kinemo" animate "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" \
    -o "$work/default.bvh" --coordinator "$coordinator" --json)"
  grep -q METHOD_GESTURE_CONTROLLER <<<"$summary" || { echo "FAIL: the user's coordinator config was not used: $summary"; exit 1; }
fi
# The stores through the coordinator's one address: a model trained by the
# inference service from a corpus sent by the CLI, and a cube pushed to the
# cube tracker, are listed there.
"$kinemo" crf corpus --out "$work/corpus" \
  --speech "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" \
  --gestures "$src/tests/data/motion/dataset-1_bye_normal_001.bvh" >/dev/null
"$kinemo" crf train --corpus "$work/corpus" --states 3 --window 2 --clusters 3 --restarts 1 \
  --server "$coordinator" --id stacktest 2>/dev/null
"$kinemo" cube push "$src/tests/data/cube/vleo.cube" --id stacktest --server "$coordinator"
listed="$("$kinemo" artifacts ls --server "$coordinator" 2>/dev/null)"
echo "$listed"
grep -q "models/stacktest " <<<"$listed" || { echo "FAIL: the trained model is not listed"; exit 1; }
grep -q "cubes/stacktest " <<<"$listed" || { echo "FAIL: the pushed cube is not listed"; exit 1; }
if [[ "$tls" == tls ]]; then
  # The refused clients left every service healthy (health over mutual TLS).
  for p in "$bridge" "$coordinator"; do "$health" "$p" --timeout-s 5 || { echo "FAIL: $p is not healthy"; exit 1; }; done
  # kinemo-health's old spelling of --timeout-s still works, with a note.
  "$health" "$bridge" --timeout 5 2>"$work/deprecated.txt" || { cat "$work/deprecated.txt"; echo "FAIL: --timeout no longer works"; exit 1; }
  grep -q -- "--timeout is deprecated.*use --timeout-s" "$work/deprecated.txt" || {
    cat "$work/deprecated.txt"; echo "FAIL: no deprecation note for --timeout"; exit 1; }
  # An out-of-range timeout is refused (usage, exit 2) naming the option.
  rc=0; "$health" "$bridge" --timeout-s 0 2>"$work/bad_timeout.txt" || rc=$?
  [[ $rc == 2 ]] && grep -q -- "--timeout-s: 0 is outside" "$work/bad_timeout.txt" || {
    cat "$work/bad_timeout.txt"; echo "FAIL: kinemo-health --timeout-s 0 gave exit $rc"; exit 1; }
  if [[ "$mode" == local ]]; then
    KINEMO_STACK_DIR="$work/stack" bash "$src/deploy/local-stack.sh" status | tee "$work/status.txt"
    if grep -q " down$" "$work/status.txt"; then echo "FAIL: a service is down"; exit 1; fi
  fi
fi
# The web studio serves its page with the token the launcher made (401
# without it) and reaches the coordinator (over mutual TLS with `tls`).
if [[ -x "$build/services/studio/studio" ]]; then
  studio="http://127.0.0.1:$KINEMO_PORT_STUDIO"
  if [[ "$tls" == tls ]]; then
    # HTTPS with the studio's certificate (deploy/config/tls/studio.textproto).
    studio="https://127.0.0.1:$KINEMO_PORT_STUDIO"
    curl() { command curl --cacert "$KINEMO_TLS_DIR/ca.pem" "$@"; }
  fi
  if [[ "$mode" == local ]]; then token_file="$work/stack/secrets/studio-token"
  else token_file="$KINEMO_STUDIO_SECRETS/studio-token"; fi
  [[ "$(curl -s -o /dev/null -w '%{http_code}' "$studio/")" == 401 ]] ||
    { echo "FAIL: the studio serves $studio/ without its token"; exit 1; }
  page="$(curl -sf -H "Authorization: Bearer $(cat "$token_file")" "$studio/")" ||
    { echo "FAIL: the studio does not serve $studio/ with its token"; exit 1; }
  grep -q '<title>kinemo studio</title>' <<<"$page" || { echo "FAIL: $studio/ is not the studio's page"; exit 1; }
  for _ in $(seq 1 100); do
    studio_health="$(curl -sf "$studio/healthz" || true)"
    grep -q '"coordinator_state":"READY"' <<<"$studio_health" && break
    sleep 0.1
  done
  grep -q '"coordinator_state":"READY"' <<<"$studio_health" ||
    { echo "FAIL: the studio does not reach the coordinator: $studio_health"; exit 1; }
  # Its bundled cube videos out of the box: listed, and one attached (drawn
  # into cube_dir, read there by the cube tracker; python3-websocket).
  if /usr/bin/python3 -c 'import websocket' 2>/dev/null; then
    /usr/bin/python3 "$src/tests/integration/deploy/studio_cube_check.py" "$studio" "$token_file" \
      ${tls:+"$KINEMO_TLS_DIR/ca.pem"} || exit 1
  else
    echo "stack_test: python3-websocket missing, the studio's cube videos not checked"
  fi
fi
echo "PASS: $mode${tls:+ ($tls)} stack serves; robot_bridge -> pleo_sim round trip; session -> robot; animate; stores; studio (a bundled cube attached)"

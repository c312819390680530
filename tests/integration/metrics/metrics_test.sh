#!/usr/bin/env bash
# Prometheus metrics across the local stack (deploy/local-stack.sh on free
# ports): every service answers GET /metrics; the Vleo scenario (a session
# whose kisses move Pleo from angry to neutral through robot_bridge and
# pleo_sim) and a live animation (StreamAnimate) move the counters of the
# services they cross; Debian's Prometheus, run by the stack, scrapes every
# target and sees the counters move; the all-in-one answers GET /metrics too.
# With --tls the stack runs with KINEMO_TLS=1: every /metrics is HTTPS and asks
# for a client certificate from the CA (server.metrics.tls); the scrapes here
# present prometheus.pem as Prometheus does (deploy/prometheus/prometheus-tls.yml),
# and plain HTTP, HTTPS without a certificate and one from another CA fail.
#   metrics_test.sh SOURCE_DIR BUILD_DIR [--tls]
set -euo pipefail
src="$1" build="$2" tls="${3:-}"
kinemo="$build/services/cli/kinemo"
work="$(mktemp -d)"
unset KINEMO_TLS_CA KINEMO_TLS_CERT KINEMO_TLS_KEY KINEMO_TLS
allinone_pid=""
cleanup() {
  local rc=$?
  KINEMO_STACK_DIR="$work/stack" bash "$src/deploy/local-stack.sh" down >/dev/null 2>&1 || true
  if [[ -n "$allinone_pid" ]]; then kill -TERM "$allinone_pid" 2>/dev/null || true; wait "$allinone_pid" 2>/dev/null || true; fi
  rm -rf "$work"
  exit $rc
}
trap cleanup EXIT
source "$src/tests/integration/free_ports.sh"

export KINEMO_STACK_DIR="$work/stack"
services=(COORDINATOR PROSODY INFERENCE PLANNER CUBE_TRACKER ROBOT_BRIDGE)
# All ports distinct (the studio serves /metrics on its HTTP port).
port_vars=(KINEMO_PORT_PLEO_SIM KINEMO_PORT_STUDIO KINEMO_PORT_PROMETHEUS)
for s in "${services[@]}"; do port_vars+=("KINEMO_PORT_$s" "KINEMO_METRICS_PORT_$s"); done
export_free_ports "${port_vars[@]}"
prometheus_on=0
if command -v prometheus >/dev/null; then
  prometheus_on=1
  export KINEMO_PROMETHEUS=1
fi
certs=""
if [[ "$tls" == --tls ]]; then
  certs="$work/certs"
  bash "$src/deploy/certs.sh" --test-extras "$certs" >/dev/null
  export KINEMO_TLS=1 KINEMO_TLS_DIR="$certs"
fi
bash "$src/deploy/local-stack.sh" up "$build"
coordinator="127.0.0.1:$KINEMO_PORT_COORDINATOR"
bridge="127.0.0.1:$KINEMO_PORT_ROBOT_BRIDGE"
if [[ -n "$certs" ]]; then
  export KINEMO_TLS_CA="$certs/ca.pem" KINEMO_TLS_CERT="$certs/cli.pem" KINEMO_TLS_KEY="$certs/cli.key"
fi

scrape() {  # SERVICE -> its /metrics on stdout
  local var="KINEMO_METRICS_PORT_$1"
  if [[ -n "$certs" ]]; then
    curl -sf --max-time 5 --cacert "$certs/ca.pem" --cert "$certs/prometheus.pem" --key "$certs/prometheus.key" \
      "https://127.0.0.1:${!var}/metrics"
  else
    curl -sf --max-time 5 "http://127.0.0.1:${!var}/metrics"
  fi
}
if [[ -n "$certs" ]]; then
  # Refused: plain HTTP, no client certificate, another CA's, an expired one.
  for s in "${services[@]}"; do
    var="KINEMO_METRICS_PORT_$s"
    url="https://127.0.0.1:${!var}/metrics"
    if curl -sf --max-time 5 "http://127.0.0.1:${!var}/metrics" >/dev/null 2>&1; then
      echo "FAIL: $s serves /metrics over plain HTTP with server.metrics.tls"; exit 1; fi
    if curl -sf --max-time 5 --cacert "$certs/ca.pem" "$url" >/dev/null 2>&1; then
      echo "FAIL: $s serves /metrics over HTTPS without a client certificate"; exit 1; fi
    if curl -sf --max-time 5 --cacert "$certs/ca.pem" --cert "$certs/stranger.pem" --key "$certs/stranger.key" \
        "$url" >/dev/null 2>&1; then
      echo "FAIL: $s serves /metrics to a client certificate from another CA"; exit 1; fi
    if curl -sf --max-time 5 --cacert "$certs/ca.pem" --cert "$certs/expired.pem" --key "$certs/expired.key" \
        "$url" >/dev/null 2>&1; then
      echo "FAIL: $s serves /metrics to an expired client certificate"; exit 1; fi
  done
  echo "every service refuses /metrics over plain HTTP, without a client certificate, with another CA's or an expired one"
fi
# Sum of a metric's samples whose line matches a label filter (a regex).
sum_of() {  # FILE NAME [LABEL-REGEX]
  awk -v name="$2" -v filt="${3:-}" '
    $1 ~ ("^" name "({|$)") && (filt == "" || $1 ~ filt) { s += $NF }
    END { printf "%.0f\n", s + 0 }' "$1"
}
for s in "${services[@]}"; do
  scrape "$s" >"$work/before_$s.txt" || { echo "FAIL: $s does not answer GET /metrics"; exit 1; }
  grep -q "^# TYPE kinemo_rpc_started_total counter" "$work/before_$s.txt" || {
    echo "FAIL: $s serves no RPC counters (the health probes count)"; head -20 "$work/before_$s.txt"; exit 1; }
  echo "$s: GET /metrics ok ($(grep -c '^kinemo_' "$work/before_$s.txt") kinemo samples)"
done

# The Vleo scenario: an angry Pleo gets kisses and turns neutral.
"$kinemo" session open pleo --id metricstest --initial angry --coordinator "$coordinator"
scrape COORDINATOR >"$work/open.txt"
[[ "$(sum_of "$work/open.txt" kinemo_coordinator_sessions)" == 1 ]] || {
  echo "FAIL: kinemo_coordinator_sessions is not 1 with one session open"; grep coordinator_sessions "$work/open.txt"; exit 1; }
deadline=$((SECONDS + 15))
until "$kinemo" robot status pleo --bridge "$bridge" | grep -q "shows angry"; do
  (( SECONDS < deadline )) || { echo "FAIL: the session did not make Pleo angry"; exit 1; }
  sleep 0.2
done
"$kinemo" session act metricstest kisses -i 1 --coordinator "$coordinator"
deadline=$((SECONDS + 30))
until "$kinemo" robot status pleo --bridge "$bridge" | grep -q "shows neutral"; do
  (( SECONDS < deadline )) || { echo "FAIL: Pleo did not turn neutral within 30 s of kisses"; exit 1; }
  sleep 0.5
done
"$kinemo" session close metricstest --coordinator "$coordinator"
# Speech -> motion, live: StreamAnimate across prosody, inference and planner.
"$kinemo" animate "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" --stream \
  -o "$work/live.bvh" --coordinator "$coordinator" >/dev/null

for s in "${services[@]}"; do scrape "$s" >"$work/after_$s.txt"; done
moved() {  # SERVICE METHOD-REGEX WHAT
  local b a
  b="$(sum_of "$work/before_$1.txt" kinemo_rpc_handled_total "$2")"
  a="$(sum_of "$work/after_$1.txt" kinemo_rpc_handled_total "$2")"
  echo "$1 $3: kinemo_rpc_handled_total $b -> $a"
  (( a > b )) || { echo "FAIL: $1's $3 calls did not move kinemo_rpc_handled_total"; exit 1; }
}
moved COORDINATOR 'CoordinatorService/(OpenSession|Act|CloseSession)' "session"
# (Labels come sorted: code before method.)
moved COORDINATOR 'code="OK",method="[^"]*CoordinatorService/StreamAnimate"' "StreamAnimate"
moved ROBOT_BRIDGE 'code="OK",method="[^"]*RobotBridgeService/SetEmotion"' "SetEmotion"
emotions="$(sum_of "$work/after_ROBOT_BRIDGE.txt" kinemo_rpc_handled_total 'code="OK",method="[^"]*RobotBridgeService/SetEmotion"')"
(( emotions >= 2 )) || { echo "FAIL: the bridge took $emotions emotion commands; angry then neutral make 2"; exit 1; }
moved PROSODY 'ProsodyService/StreamAnalyze' "StreamAnalyze"
moved INFERENCE 'InferenceService/' "inference"
moved PLANNER 'PlannerService/Control' "Control"
lag="$(sum_of "$work/after_COORDINATOR.txt" kinemo_stream_animate_motion_lag_seconds_count)"
echo "coordinator: kinemo_stream_animate_motion_lag_seconds_count $lag"
(( lag > 0 )) || { echo "FAIL: no motion lag observed"; exit 1; }
grep -q '^kinemo_robot_link_up{robot="pleo"} 1' "$work/after_ROBOT_BRIDGE.txt" || {
  echo "FAIL: kinemo_robot_link_up is not 1 for pleo"; grep robot_ "$work/after_ROBOT_BRIDGE.txt"; exit 1; }
[[ "$(sum_of "$work/after_COORDINATOR.txt" kinemo_coordinator_sessions)" == 0 ]] || { echo "FAIL: the closed session is still counted"; exit 1; }
echo "sample (coordinator, after the scenario):"
grep -E '^kinemo_(rpc_handled_total\{.*(StreamAnimate|Act)|coordinator_|stream_animate_motion_lag_seconds_(count|sum))' "$work/after_COORDINATOR.txt" | head -12

if [[ $prometheus_on == 1 ]]; then
  # Prometheus scrapes every 5 s: wait until every target is up and has a
  # sample of the counters taken after the scenario.
  api="http://127.0.0.1:$KINEMO_PORT_PROMETHEUS/api/v1"
  deadline=$((SECONDS + 60))
  until
    curl -sf "$api/targets" >"$work/targets.json" &&
    python3 - "$work/targets.json" <<'PY'
import json, sys
targets = json.load(open(sys.argv[1]))["data"]["activeTargets"]
jobs = {t["labels"]["job"]: t["health"] for t in targets}
want = {"coordinator", "prosody", "inference", "planner", "cube_tracker", "robot_bridge", "studio"}
sys.exit(0 if want <= set(jobs) and all(jobs[j] == "up" for j in want) else 1)
PY
  do
    (( SECONDS < deadline )) || { echo "FAIL: Prometheus does not see every target up"; cat "$work/targets.json"; exit 1; }
    sleep 1
  done
  echo "prometheus: all 7 targets up (six services and the studio)${certs:+, over HTTPS with its client certificate}"
  query='sum by (job) (kinemo_rpc_handled_total{method=~".*(StreamAnimate|StreamAnalyze|Control|SetEmotion)"})'
  deadline=$((SECONDS + 30))
  until
    curl -sf "$api/query" --data-urlencode "query=$query" >"$work/query.json" &&
    python3 - "$work/query.json" <<'PY'
import json, sys
result = json.load(open(sys.argv[1]))["data"]["result"]
jobs = {r["metric"]["job"]: float(r["value"][1]) for r in result}
print("prometheus:", jobs)
sys.exit(0 if all(jobs.get(j, 0) > 0 for j in ("coordinator", "prosody", "planner", "robot_bridge")) else 1)
PY
  do
    (( SECONDS < deadline )) || { echo "FAIL: Prometheus did not record the scenario's calls"; cat "$work/query.json"; exit 1; }
    sleep 1
  done
else
  echo "prometheus not installed: the real-scrape part is skipped"
fi

# The all-in-one: one GET /metrics for every service in the process (plaintext).
unset KINEMO_TLS_CA KINEMO_TLS_CERT KINEMO_TLS_KEY
"$build/services/allinone/kinemo_allinone" --port 0 --port-file "$work/aio.port" --metrics-port 0 \
  --metrics-port-file "$work/aio.metrics" >"$work/aio.log" 2>&1 &
allinone_pid=$!
for _ in $(seq 1 600); do [[ -s "$work/aio.port" ]] && break; kill -0 "$allinone_pid" || break; sleep 0.05; done
[[ -s "$work/aio.port" ]] || { echo "FAIL: kinemo_allinone did not start"; tail -5 "$work/aio.log"; exit 1; }
"$kinemo" session open pleo --id aio --coordinator "127.0.0.1:$(cat "$work/aio.port")" >/dev/null 2>&1 || true
curl -sf --max-time 5 "http://127.0.0.1:$(cat "$work/aio.metrics")/metrics" >"$work/aio.txt" || { echo "FAIL: the all-in-one does not answer GET /metrics"; exit 1; }
grep -q '^kinemo_rpc_started_total{method="/kinemo.coordinator.v1.CoordinatorService/OpenSession"}' "$work/aio.txt" || {
  echo "FAIL: the all-in-one's /metrics counts no calls"; head -30 "$work/aio.txt"; exit 1; }
echo "all-in-one: GET /metrics ok"
scraped=""
[[ $prometheus_on == 1 ]] && scraped="; Prometheus scraped every target"
echo "PASS: every service and the all-in-one serve /metrics${certs:+ (the services over mutual TLS)}; the scenario moved the counters$scraped"

#!/usr/bin/env bash
# Runs the compose topology as plain processes on loopback (no containers):
# the same services, ports and configuration files as deploy/docker-compose.yml,
# with container host names and paths rewritten for this machine.
#   deploy/local-stack.sh up [BUILD_DIR] [--config DIR]   start every built service, wait until healthy
#   deploy/local-stack.sh down              stop the processes this script started
#   deploy/local-stack.sh status            health of each service
# Configuration: deploy/config/<service>.textproto, rewritten for loopback into
# $KINEMO_STACK_DIR/config at every `up`; a service whose file is in the folder
# given with --config DIR (or $KINEMO_STACK_CONFIG) uses that file as it is
# (write it for loopback: host 127.0.0.1, the ports below, local paths).
# Metrics: each service serves Prometheus' GET /metrics on 127.0.0.1 at the
# ports of deploy/config (9460 coordinator … 9465 robot_bridge), or
# KINEMO_METRICS_PORT_<SERVICE>. KINEMO_PROMETHEUS=1 also runs Debian's
# prometheus (/usr/bin/prometheus) on 127.0.0.1:${KINEMO_PORT_PROMETHEUS:-9090}
# with deploy/prometheus/prometheus.yml rewritten for loopback, scraping them all
# (with KINEMO_TLS=1: prometheus-tls.yml, /metrics over HTTPS with Prometheus'
# client certificate from deploy/certs.sh).
# State (configs, artifact stores, logs, pid files): $KINEMO_STACK_DIR (default ./out/local-stack).
# The studio's token: $KINEMO_STACK_DIR/secrets/studio-token (made at the
# first `up`; `up` prints the studio's URL with it).
# Ports: the compose defaults, or KINEMO_PORT_<SERVICE> (e.g. KINEMO_PORT_PROSODY=0
# is not allowed here: give a free port; tests pick them).
# Mutual TLS: KINEMO_TLS=1 ... up makes (or keeps) the material with
# deploy/certs.sh in $KINEMO_TLS_DIR (default $KINEMO_STACK_DIR/certs) and
# merges the overlays of deploy/config/tls/ over each service's options: every
# gRPC server requires a client certificate from the CA, the coordinator
# presents its own to the others, the health probes present cli.pem. Clients
# then need --ca/--cert/--key or KINEMO_TLS_CA/KINEMO_TLS_CERT/KINEMO_TLS_KEY
# (up prints them). `status` and `down` find the mode in the state directory.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
cmd="${1:-up}"
shift || true
user_config="${KINEMO_STACK_CONFIG:-}"
build_arg=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --config) user_config="${2:?--config needs a folder}"; shift 2 ;;
    --config=*) user_config="${1#--config=}"; shift ;;
    *) build_arg="$1"; shift ;;
  esac
done
build="$(realpath "${build_arg:-$root/build}")"
if [[ -n "$user_config" ]]; then
  [[ -d "$user_config" ]] || { echo "local-stack: --config: $user_config is not a folder" >&2; exit 2; }
  user_config="$(realpath "$user_config")"
fi
state="${KINEMO_STACK_DIR:-$root/out/local-stack}"
health="$build/services/cli/kinemo-health"

P_PLEO_SIM="${KINEMO_PORT_PLEO_SIM:-1502}"
P_ROBOT_BRIDGE="${KINEMO_PORT_ROBOT_BRIDGE:-50055}"
P_PROSODY="${KINEMO_PORT_PROSODY:-50051}"
P_INFERENCE="${KINEMO_PORT_INFERENCE:-50052}"
P_PLANNER="${KINEMO_PORT_PLANNER:-50053}"
P_CUBE_TRACKER="${KINEMO_PORT_CUBE_TRACKER:-50054}"
P_COORDINATOR="${KINEMO_PORT_COORDINATOR:-50050}"
P_STUDIO="${KINEMO_PORT_STUDIO:-8080}"
M_COORDINATOR="${KINEMO_METRICS_PORT_COORDINATOR:-9460}"
M_PROSODY="${KINEMO_METRICS_PORT_PROSODY:-9461}"
M_INFERENCE="${KINEMO_METRICS_PORT_INFERENCE:-9462}"
M_PLANNER="${KINEMO_METRICS_PORT_PLANNER:-9463}"
M_CUBE_TRACKER="${KINEMO_METRICS_PORT_CUBE_TRACKER:-9464}"
M_ROBOT_BRIDGE="${KINEMO_METRICS_PORT_ROBOT_BRIDGE:-9465}"
P_PROMETHEUS="${KINEMO_PORT_PROMETHEUS:-9090}"
# name  binary  port  health-kind
SERVICES=(
  "pleo_sim services/pleo_sim/pleo_sim $P_PLEO_SIM tcp"
  "robot_bridge services/robot_bridge/robot_bridge $P_ROBOT_BRIDGE grpc"
  "prosody services/prosody/prosody $P_PROSODY grpc"
  "inference services/inference/inference $P_INFERENCE grpc"
  "planner services/planner/planner $P_PLANNER grpc"
  "cube_tracker services/cube_tracker/cube_tracker $P_CUBE_TRACKER grpc"
  "coordinator services/coordinator/coordinator $P_COORDINATOR grpc"
  "studio services/studio/studio $P_STUDIO http"
)

localize() {  # container config -> loopback config
  sed -e "s#/etc/kinemo-tls#$certs#g" \
      -e "s#/etc/kinemo-secrets#$state/secrets#g" \
      -e 's/host: "0.0.0.0"/host: "127.0.0.1"/' \
      -e 's#"\(pleo_sim\|robot_bridge\|prosody\|inference\|planner\|cube_tracker\|coordinator\|studio\)\(:[0-9]\+\)\?"#"127.0.0.1\2"#g' \
      -e "s#/var/lib/kinemo#$state/var#g" \
      -e "s#/usr/local/share/kinemo/gestures#$root/tests/data#g" \
      -e "s#/usr/local/share/kinemo/store#$build/share/kinemo/store#g" \
      -e "s#/etc/kinemo#$state/config#g" \
      -e "s/\\b1502\\b/$P_PLEO_SIM/g" -e "s/\\b50055\\b/$P_ROBOT_BRIDGE/g" \
      -e "s/\\b50051\\b/$P_PROSODY/g" -e "s/\\b50052\\b/$P_INFERENCE/g" \
      -e "s/\\b50053\\b/$P_PLANNER/g" -e "s/\\b50054\\b/$P_CUBE_TRACKER/g" \
      -e "s/\\b50050\\b/$P_COORDINATOR/g" -e "s/\\b8080\\b/$P_STUDIO/g" \
      -e "s/\\b9460\\b/$M_COORDINATOR/g" -e "s/\\b9461\\b/$M_PROSODY/g" \
      -e "s/\\b9462\\b/$M_INFERENCE/g" -e "s/\\b9463\\b/$M_PLANNER/g" \
      -e "s/\\b9464\\b/$M_CUBE_TRACKER/g" -e "s/\\b9465\\b/$M_ROBOT_BRIDGE/g" \
      -e "s#/usr/local/share/kinemo/samples#$root/tests/data/speech#g" "$1"
}

# TLS material of a stack started with KINEMO_TLS=1 (recorded in the state).
certs=""
if [[ -f "$state/tls-dir" ]]; then certs="$(cat "$state/tls-dir")"; fi

check() {  # name port kind
  if [[ "$3" == tcp ]]; then "$health" --tcp "127.0.0.1:$2" --timeout-s 1 2>/dev/null
  elif [[ "$3" == http && -n "$certs" ]]; then
    curl -sf --max-time 1 --cacert "$certs/ca.pem" "https://127.0.0.1:$2/healthz" >/dev/null 2>&1
  elif [[ "$3" == http ]]; then curl -sf --max-time 1 "http://127.0.0.1:$2/healthz" >/dev/null 2>&1
  elif [[ -n "$certs" ]]; then
    "$health" "127.0.0.1:$2" --timeout-s 1 --ca "$certs/ca.pem" --cert "$certs/cli.pem" --key "$certs/cli.key" 2>/dev/null
  else "$health" "127.0.0.1:$2" --timeout-s 1 2>/dev/null; fi
}

up() {
  [[ -x "$health" ]] || { echo "local-stack: build first (missing $health)" >&2; exit 2; }
  mkdir -p "$state/secrets" "$state/config/tls" "$state/var/inference" "$state/var/planner" "$state/var/cube_tracker" "$state/var/coordinator" "$state/var/media" "$state/var/library" "$state/logs" "$state/pids"
  if [[ "${KINEMO_TLS:-0}" == 1 ]]; then
    certs="$(realpath -m "${KINEMO_TLS_DIR:-${certs:-$state/certs}}")"
    bash "$here/certs.sh" "$certs"
    echo "$certs" >"$state/tls-dir"
  elif [[ -n "$certs" ]]; then
    # A plaintext start over a stack directory that ran with TLS.
    if compgen -G "$state/pids/*" >/dev/null; then
      echo "local-stack: this stack runs with mutual TLS ($certs); stop it first or use KINEMO_TLS=1" >&2; exit 2
    fi
    rm -f "$state/tls-dir"; certs=""
  fi
  for f in "$here"/config/*.textproto; do
    local name; name="$(basename "$f")"
    if [[ -n "$user_config" && -f "$user_config/$name" ]]; then
      cp "$user_config/$name" "$state/config/$name"
      echo "local-stack: ${name%.textproto} uses $user_config/$name"
    else
      localize "$f" >"$state/config/$name"
    fi
  done
  # With TLS, the overlays are merged over each service's file (the user's too).
  if [[ -n "$certs" ]]; then
    for f in "$here"/config/tls/*.textproto; do localize "$f" >"$state/config/tls/$(basename "$f")"; done
  fi
  # The studio's token (StudioAuth; deploy/config/studio.textproto reads it
  # from /etc/kinemo-secrets/studio-token): made once, kept across restarts.
  if [[ ! -s "$state/secrets/studio-token" ]]; then
    (umask 077; od -An -tx1 -N24 /dev/urandom | tr -d ' \n' >"$state/secrets/studio-token")
  fi
  local started=()
  for s in "${SERVICES[@]}"; do
    read -r name bin port kind <<<"$s"
    [[ -x "$build/$bin" ]] || { echo "local-stack: $name not built, skipped"; continue; }
    if [[ -f "$state/pids/$name" ]] && kill -0 "$(cat "$state/pids/$name")" 2>/dev/null; then
      echo "local-stack: $name already running (pid $(cat "$state/pids/$name"))"; continue
    fi
    if [[ "$name" == pleo_sim ]]; then
      args=(--tcp "127.0.0.1:$port")
    else
      args=(--config "$state/config/$name.textproto")
      [[ -n "$certs" ]] && args+=(--config "$state/config/tls/$name.textproto")
    fi
    "$build/$bin" "${args[@]}" >"$state/logs/$name.log" 2>&1 &
    echo $! >"$state/pids/$name"
    started+=("$name $port $kind")
  done
  for s in "${started[@]}"; do
    read -r name port kind <<<"$s"
    local ok=0
    for _ in $(seq 1 60); do
      if check "$name" "$port" "$kind"; then ok=1; break; fi
      kill -0 "$(cat "$state/pids/$name")" 2>/dev/null || break
    done
    if [[ $ok == 1 ]]; then echo "local-stack: $name ready on 127.0.0.1:$port"
    else
      echo "local-stack: $name failed to start; see $state/logs/$name.log" >&2
      tail -5 "$state/logs/$name.log" >&2
      down
      exit 1
    fi
  done
  if [[ "${KINEMO_PROMETHEUS:-0}" == 1 ]]; then start_prometheus; fi
  if [[ -x "$build/services/studio/studio" ]]; then
    echo "local-stack: the studio: http${certs:+s}://127.0.0.1:$P_STUDIO/?token=$(cat "$state/secrets/studio-token")" \
         "(token in $state/secrets/studio-token)"
  fi
  if [[ -n "$certs" ]]; then
    echo "local-stack: mutual TLS on every gRPC hop (material in $certs); clients need:"
    echo "  export KINEMO_TLS_CA=$certs/ca.pem KINEMO_TLS_CERT=$certs/cli.pem KINEMO_TLS_KEY=$certs/cli.key"
  fi
}

# Debian's prometheus scraping every service's /metrics (the scrape config
# and alert rules of deploy/prometheus, rewritten for loopback).
start_prometheus() {
  command -v prometheus >/dev/null || { echo "local-stack: KINEMO_PROMETHEUS=1 needs Debian's prometheus (deploy/install-deps.sh)" >&2; down; exit 2; }
  if [[ -f "$state/pids/prometheus" ]] && kill -0 "$(cat "$state/pids/prometheus")" 2>/dev/null; then
    echo "local-stack: prometheus already running"; return
  fi
  mkdir -p "$state/config/prometheus/rules" "$state/var/prometheus"
  # With TLS every /metrics is HTTPS and asks for Prometheus' client
  # certificate (deploy/config/tls/); the studio serves HTTPS.
  localize "$here/prometheus/prometheus${certs:+-tls}.yml" >"$state/config/prometheus/prometheus.yml"
  cp "$here"/prometheus/rules/*.yml "$state/config/prometheus/rules/"
  prometheus --config.file="$state/config/prometheus/prometheus.yml" --storage.tsdb.path="$state/var/prometheus" \
    --web.listen-address="127.0.0.1:$P_PROMETHEUS" >"$state/logs/prometheus.log" 2>&1 &
  echo $! >"$state/pids/prometheus"
  for _ in $(seq 1 100); do
    if "$health" --tcp "127.0.0.1:$P_PROMETHEUS" --timeout-s 1 2>/dev/null; then
      echo "local-stack: prometheus ready on http://127.0.0.1:$P_PROMETHEUS"; return
    fi
    kill -0 "$(cat "$state/pids/prometheus")" 2>/dev/null || break
    sleep 0.1
  done
  echo "local-stack: prometheus failed to start; see $state/logs/prometheus.log" >&2
  tail -5 "$state/logs/prometheus.log" >&2
  down
  exit 1
}

down() {
  shopt -s nullglob
  for p in "$state"/pids/*; do
    local pid; pid="$(cat "$p")"
    if kill -0 "$pid" 2>/dev/null; then kill -TERM "$pid"; fi
  done
  for p in "$state"/pids/*; do
    local pid; pid="$(cat "$p")"
    for _ in $(seq 1 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -0 "$pid" 2>/dev/null && kill -KILL "$pid"
    echo "local-stack: stopped $(basename "$p")"
    rm -f "$p"
  done
  rm -f "$state/tls-dir"
}

status() {
  for s in "${SERVICES[@]}"; do
    read -r name bin port kind <<<"$s"
    if check "$name" "$port" "$kind"; then echo "$name 127.0.0.1:$port serving"; else echo "$name 127.0.0.1:$port down"; fi
  done
}

case "$cmd" in
  up) up ;;
  down) down ;;
  status) status ;;
  *) echo "usage: local-stack.sh up [BUILD_DIR] [--config DIR] | down | status" >&2; exit 2 ;;
esac

#!/usr/bin/env bash
# Runs deploy/docker-compose.yml under podman (no Docker engine needed):
#   deploy/compose.sh up [BUILD_DIR]   build the runtime image if missing, start, wait until healthy
#   deploy/compose.sh down             stop and remove the containers
#   deploy/compose.sh ps|logs [...]    passed to docker-compose
# Env: KINEMO_COMPOSE_PROJECT (default kinemo), KINEMO_PORT_<SERVICE> host ports,
# KINEMO_REBUILD_IMAGE=1 to rebuild the image from BUILD_DIR.
# Mutual TLS: KINEMO_TLS=1 ... up makes (or keeps) the material with
# deploy/certs.sh in $KINEMO_TLS_DIR (default ./out/certs), copies it for the
# containers' user into $KINEMO_TLS_MOUNT (default ./out/compose-certs) and
# adds deploy/docker-compose.tls.yml; clients then need --ca/--cert/--key or
# KINEMO_TLS_CA/KINEMO_TLS_CERT/KINEMO_TLS_KEY (up prints them).
# The studio's token (StudioAuth): $KINEMO_STUDIO_SECRETS/studio-token
# (default ./out/studio-secrets), made at the first `up`, mounted at
# /etc/kinemo-secrets; `up` prints the studio's URL with it.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
source "$here/container/podman-env.sh"
kinemo_podman_available || { echo "compose: needs podman, runc and docker-compose (deploy/install-deps.sh)" >&2; exit 2; }
project="${KINEMO_COMPOSE_PROJECT:-kinemo}"
image="${KINEMO_IMAGE:-localhost/kinemo/runtime:latest}"
cmd="${1:-up}"; shift || true
kinemo_podman_start
trap kinemo_podman_stop EXIT
tls="${KINEMO_TLS:-0}"
files=(-f "$here/docker-compose.yml")
if [[ "$tls" == 1 && "$cmd" == up ]]; then
  certs="$(realpath -m "${KINEMO_TLS_DIR:-$root/out/certs}")"
  export KINEMO_TLS_MOUNT="$(realpath -m "${KINEMO_TLS_MOUNT:-$root/out/compose-certs}")"
  bash "$here/certs.sh" "$certs"
  # The containers run as uid 10001: a copy of the material that it can read
  # (the CA's key stays out).
  if [[ "$(id -u)" == 0 ]]; then rm -rf "$KINEMO_TLS_MOUNT"; else podman unshare rm -rf "$KINEMO_TLS_MOUNT"; fi
  mkdir -p "$KINEMO_TLS_MOUNT"
  cp "$certs"/*.pem "$certs"/*.key "$KINEMO_TLS_MOUNT/"
  rm -f "$KINEMO_TLS_MOUNT/ca.key" "$KINEMO_TLS_MOUNT/other-ca.key"
  chmod 0500 "$KINEMO_TLS_MOUNT"
  chmod 0400 "$KINEMO_TLS_MOUNT"/*
  if [[ "$(id -u)" == 0 ]]; then chown -R 10001:10001 "$KINEMO_TLS_MOUNT"
  else podman unshare chown -R 10001:10001 "$KINEMO_TLS_MOUNT"; fi
  files+=(-f "$here/docker-compose.tls.yml")
fi
dc() { docker-compose -p "$project" "${files[@]}" "$@"; }

case "$cmd" in
  up)
    build="${1:-$root/build}"
    if [[ "${KINEMO_REBUILD_IMAGE:-0}" == 1 ]] || ! podman image exists "$image"; then
      bash "$here/container/build-images.sh" "$build"
    fi
    # The studio's token, readable by the containers' user only.
    export KINEMO_STUDIO_SECRETS="$(realpath -m "${KINEMO_STUDIO_SECRETS:-$root/out/studio-secrets}")"
    if [[ ! -s "$KINEMO_STUDIO_SECRETS/studio-token" ]]; then
      mkdir -p "$KINEMO_STUDIO_SECRETS"
      (umask 077; od -An -tx1 -N24 /dev/urandom | tr -d ' \n' >"$KINEMO_STUDIO_SECRETS/studio-token")
    fi
    studio_token="$(cat "$KINEMO_STUDIO_SECRETS/studio-token" 2>/dev/null || podman unshare cat "$KINEMO_STUDIO_SECRETS/studio-token")"
    if [[ "$(id -u)" == 0 ]]; then chown -R 10001:10001 "$KINEMO_STUDIO_SECRETS"
    else podman unshare chown -R 10001:10001 "$KINEMO_STUDIO_SECRETS"; fi
    # The studio's cube videos (volume studio_cube) are mounted at studio/ in
    # the cube tracker's read-only media folder: the mount point must exist.
    media="${KINEMO_MEDIA_DIR:-./media}"
    [[ "$media" == /* ]] || media="$here/$media"
    mkdir -p "$media/studio"
    dc up -d
    health="$build/services/cli/kinemo-health"
    probe=()
    [[ "$tls" == 1 ]] && probe=(--ca "$certs/ca.pem" --cert "$certs/cli.pem" --key "$certs/cli.key")
    declare -A port=([pleo_sim]="${KINEMO_PORT_PLEO_SIM:-1502}" [robot_bridge]="${KINEMO_PORT_ROBOT_BRIDGE:-50055}"
      [prosody]="${KINEMO_PORT_PROSODY:-50051}" [inference]="${KINEMO_PORT_INFERENCE:-50052}"
      [planner]="${KINEMO_PORT_PLANNER:-50053}" [cube_tracker]="${KINEMO_PORT_CUBE_TRACKER:-50054}"
      [coordinator]="${KINEMO_PORT_COORDINATOR:-50050}" [studio]="${KINEMO_PORT_STUDIO:-8080}")
    for name in pleo_sim robot_bridge prosody inference planner cube_tracker coordinator studio; do
      ok=0
      for _ in $(seq 1 60); do
        if [[ $name == studio && "$tls" == 1 ]]; then
          curl -sf --cacert "$certs/ca.pem" "https://127.0.0.1:${port[$name]}/healthz" >/dev/null 2>&1 && { ok=1; break; }
        elif [[ $name == studio ]]; then curl -sf "http://127.0.0.1:${port[$name]}/healthz" >/dev/null 2>&1 && { ok=1; break; }
        elif [[ $name == pleo_sim ]]; then "$health" --tcp "127.0.0.1:${port[$name]}" --timeout-s 1 2>/dev/null && { ok=1; break; }
        else "$health" "127.0.0.1:${port[$name]}" --timeout-s 1 "${probe[@]}" 2>/dev/null && { ok=1; break; }; fi
        sleep 0.5
      done
      if [[ $ok == 1 ]]; then echo "compose: $name serving on 127.0.0.1:${port[$name]}"
      else echo "compose: $name not ready; its log:" >&2; dc logs --tail 20 "$name" >&2; exit 1; fi
    done
    scheme=http; [[ "$tls" == 1 ]] && scheme=https
    echo "compose: the studio: $scheme://127.0.0.1:${port[studio]}/?token=$studio_token"
    if [[ "$tls" == 1 ]]; then
      echo "compose: mutual TLS on every gRPC hop (material in $certs); clients need:"
      echo "  export KINEMO_TLS_CA=$certs/ca.pem KINEMO_TLS_CERT=$certs/cli.pem KINEMO_TLS_KEY=$certs/cli.key"
    fi
    ;;
  down) dc down -v --remove-orphans ;;
  *) dc "$cmd" "$@" ;;
esac

# Sourced by scripts that run compose files under podman on a machine without
# a Docker engine (Debian 12: podman 4.3 + runc + docker-compose 1.29):
#   source deploy/container/podman-env.sh && kinemo_podman_start
# Writes a containers.conf (runc, cgroupfs, file events, raised ulimits),
# starts `podman system service` on a private socket and exports DOCKER_HOST
# for docker-compose. kinemo_podman_stop ends the service this shell started.
KINEMO_PODMAN_DIR="${KINEMO_PODMAN_DIR:-${TMPDIR:-/tmp}/kinemo-podman-$(id -u)}"

kinemo_podman_available() {
  command -v podman >/dev/null && command -v docker-compose >/dev/null && command -v runc >/dev/null
}

# kinemo_podman_test_ready [compose]: for the tests that run containers. Exits
# 77 (ctest's skip) with the reason when podman cannot run here as root (with
# `compose`: or runc / docker-compose is missing); returns when it can.
kinemo_podman_test_ready() {
  if [[ "${1:-}" == compose ]]; then
    kinemo_podman_available || { echo "SKIP: podman, runc or docker-compose not installed"; exit 77; }
  else
    command -v podman >/dev/null || { echo "SKIP: podman not installed"; exit 77; }
  fi
  [[ "$(id -u)" == 0 ]] || { echo "SKIP: rootless podman is not set up here; run as root"; exit 77; }
  podman info >/dev/null 2>&1 || { echo "SKIP: podman cannot run here: $(podman info 2>&1 | tail -1)"; exit 77; }
}

kinemo_podman_start() {
  mkdir -p "$KINEMO_PODMAN_DIR"
  cat >"$KINEMO_PODMAN_DIR/containers.conf" <<'CONF'
[containers]
default_ulimits = ["nofile=20000:20000", "nproc=20000:20000"]
[engine]
runtime = "runc"
cgroup_manager = "cgroupfs"
events_logger = "file"
CONF
  export CONTAINERS_CONF="$KINEMO_PODMAN_DIR/containers.conf"
  local sock="$KINEMO_PODMAN_DIR/podman.sock"
  export DOCKER_HOST="unix://$sock"
  if [[ -S "$sock" ]] && curl -s --unix-socket "$sock" http://d/_ping >/dev/null 2>&1; then
    return 0
  fi
  rm -f "$sock"
  podman system service --time=0 "unix://$sock" >"$KINEMO_PODMAN_DIR/service.log" 2>&1 &
  KINEMO_PODMAN_PID=$!
  echo "$KINEMO_PODMAN_PID" >"$KINEMO_PODMAN_DIR/service.pid"
  local i
  for i in $(seq 1 200); do
    if curl -s --unix-socket "$sock" http://d/_ping >/dev/null 2>&1; then return 0; fi
    kill -0 "$KINEMO_PODMAN_PID" 2>/dev/null || break
    sleep 0.05
  done
  echo "podman system service did not start (see $KINEMO_PODMAN_DIR/service.log)" >&2
  return 1
}

kinemo_podman_stop() {
  if [[ -n "${KINEMO_PODMAN_PID:-}" ]]; then
    kill "$KINEMO_PODMAN_PID" 2>/dev/null || true
    wait "$KINEMO_PODMAN_PID" 2>/dev/null || true
    rm -f "$KINEMO_PODMAN_DIR/podman.sock" "$KINEMO_PODMAN_DIR/service.pid"
    unset KINEMO_PODMAN_PID
  fi
}

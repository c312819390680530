# Sourced by the stack tests. `free_ports N` prints N distinct free TCP ports
# on 127.0.0.1, one per line. All N sockets stay bound until every port is
# known, so no two services of one stack are handed the same port (asking
# for one port at a time can return a port twice: CI once gave pleo_sim's
# Modbus port to cube_tracker's /metrics).
free_ports() {
  python3 - "$1" <<'PY'
import socket, sys
held = []
for _ in range(int(sys.argv[1])):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    held.append(s)
print("\n".join(str(s.getsockname()[1]) for s in held))
PY
}

# `export_free_ports VAR...` exports each named variable with its own free port.
export_free_ports() {
  local ports i=0
  mapfile -t ports < <(free_ports "$#")
  [[ ${#ports[@]} == "$#" ]] || { echo "free_ports: could not bind $# ports" >&2; return 1; }
  for v in "$@"; do export "$v=${ports[$i]}"; i=$((i + 1)); done
}

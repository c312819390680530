# Sourced by the stack tests. `free_ports N` prints N distinct free TCP ports
# on 127.0.0.1, one per line. All N sockets stay bound until every port is
# known, so no two services of one stack are handed the same port (asking
# for one port at a time can return a port twice: CI once gave pleo_sim's
# Modbus port to cube_tracker's /metrics). The ports lie below the kernel's
# ephemeral range (ip_local_port_range), which every outgoing connection and
# every bind to port 0 of the tests running beside this one draws from: CI
# once gave pleo_sim's port, free when picked, to such a socket before
# pleo_sim bound it ("Address already in use").
free_ports() {
  python3 - "$1" <<'PY'
import random, socket, sys
n = int(sys.argv[1])
try:
    lo, _ = map(int, open("/proc/sys/net/ipv4/ip_local_port_range").read().split())
except (OSError, ValueError):
    lo = 32768
candidates = list(range(max(1024, lo - 12000), lo))
random.shuffle(candidates)
held = []
for port in candidates:
    if len(held) == n:
        break
    s = socket.socket()
    try:
        s.bind(("127.0.0.1", port))
        held.append(s)
    except OSError:
        s.close()
while len(held) < n:  # no room below the range: the kernel's choice
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

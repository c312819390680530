#!/usr/bin/env bash
# `kinemo bench chaos` for half a minute (faults every 2-4 s after each
# recovery, at least 2 of them: kills, freezes, robot link drops at random
# with a fixed seed) on the process stack with replicas, under live streams,
# Acting sessions, a cube and malformed requests. Fails if an acknowledged
# Act or a session was lost, a stream hung, a fault did not recover, an Act
# was stored twice, or a malformed request got anything but INVALID_ARGUMENT
# naming its field.
#   chaos_test.sh BUILD_DIR
set -euo pipefail
build="$1"
out="$(mktemp)"
trap 'rm -f "$out"' EXIT
"$build/services/cli/kinemo" bench chaos --minutes 0.5 --gap-s 2,4 --streams 2 --act-sessions 2 --seed 7 --json \
  | tee "$out"
python3 - "$out" <<'PY'
import json, sys
r = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1])
checks = [
    ("faults >= 2", r["faults"] >= 2),
    ("acts acknowledged", r["acts_acknowledged"] > 0),
    ("acts_lost == 0", r["acts_lost"] == 0),
    ("acts_extra == 0", r["acts_extra"] == 0),
    ("sessions_lost == 0", r["sessions_lost"] == 0),
    ("streams_hung == 0", r["streams_hung"] == 0),
    ("streams completed", r["streams_ok"] > 0),
    ("every fault recovered", all(k["not_recovered"] == 0 for k in r["faults_by_kind"].values())),
    ("malformed requests sent", r["malformed_sent"] > 0),
    ("malformed requests refused naming the field", r["malformed_unexpected"] == 0),
    ("cube attached", r["cube_attaches"] > 0),
]
failed = [name for name, ok in checks if not ok]
for name, ok in checks:
    print(("ok   " if ok else "FAIL ") + name)
sys.exit(1 if failed else 0)
PY
echo "PASS: chaos_short"

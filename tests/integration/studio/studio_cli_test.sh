#!/usr/bin/env bash
# `kinemo studio --port 0 --port-file F` (issue 15's verification interface):
# the embedded stack and the studio start, the printed URL carries ?token=
# (issue 26), GET / serves the page with that token (401 without it) and
# GET /healthz reports SERVING with the coordinator connected; SIGTERM stops
# kinemo studio and every process it started. `kinemo studio --host 0.0.0.0`
# without --token-file exits 2 naming it.
#   studio_cli_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src="$1"; build="$2"
tmp="$(mktemp -d)"
pid=""
cleanup() {
  if [[ -n "$pid" ]] && kill -0 "$pid" 2>/dev/null; then kill -TERM "$pid"; wait "$pid" || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
export KINEMO_STORE_DIR="$tmp/store"
code=0; "$build/services/cli/kinemo" studio --host 0.0.0.0 --port 0 >"$tmp/open.log" 2>&1 || code=$?
[[ $code == 2 ]] && grep -q -- '--token-file' "$tmp/open.log" ||
  { echo "FAIL: kinemo studio --host 0.0.0.0 without a token exited $code:"; cat "$tmp/open.log"; exit 1; }
"$build/services/cli/kinemo" studio --port 0 --port-file "$tmp/port" >"$tmp/out.log" 2>&1 &
pid=$!
for _ in $(seq 1 1200); do
  [[ -s "$tmp/port" ]] && break
  kill -0 "$pid" 2>/dev/null || { echo "FAIL: kinemo studio exited:"; cat "$tmp/out.log"; exit 1; }
  sleep 0.05
done
[[ -s "$tmp/port" ]] || { echo "FAIL: no port file after 60 s"; cat "$tmp/out.log"; exit 1; }
port="$(cat "$tmp/port")"
url="http://127.0.0.1:$port"
# The URL with the token is printed once the studio listens.
printed=""
for _ in $(seq 1 200); do
  printed="$(grep -o "kinemo studio: http://127.0.0.1:$port/?token=[0-9a-f]*" "$tmp/out.log" || true)"
  [[ -n "$printed" ]] && break
  sleep 0.05
done
[[ -n "$printed" ]] || { echo "FAIL: no URL with ?token= printed"; cat "$tmp/out.log"; exit 1; }
token="${printed##*?token=}"
[[ "$(curl -s -o /dev/null -w '%{http_code}' "$url/")" == 401 ]] || { echo "FAIL: GET / without the token is not 401"; exit 1; }
curl() { command curl -H "Authorization: Bearer $token" "$@"; }
page="$(curl -sf "$url/")"
grep -q '<title>kinemo studio</title>' <<<"$page" || { echo "FAIL: GET / is not the page"; exit 1; }
script="$(curl -sf "$url/static/studio.js")"
grep -q 'window.kinemoStudio' <<<"$script" || { echo "FAIL: GET /static/studio.js"; exit 1; }
# The coordinator channel connects (IDLE until the first probe asks it to).
state=""
for _ in $(seq 1 200); do
  health="$(curl -sf "$url/healthz")"
  state="$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["coordinator_state"])' "$health")"
  [[ "$state" == READY ]] && break
  sleep 0.05
done
grep -q '"status":"SERVING"' <<<"$health" || { echo "FAIL: /healthz: $health"; exit 1; }
[[ "$state" == READY ]] || { echo "FAIL: the coordinator is $state: $health"; exit 1; }
[[ "$(curl -s -o /dev/null -w '%{http_code}' -X POST "$url/")" == 405 ]] || { echo "FAIL: POST / is not 405"; exit 1; }
[[ "$(curl -s -o /dev/null -w '%{http_code}' --path-as-is "$url/static/../../etc/passwd")" == 404 ]] ||
  { echo "FAIL: a path outside the page's folder was served"; exit 1; }
kill -TERM "$pid"
code=0; wait "$pid" || code=$?
pid=""
[[ $code == 0 ]] || { echo "FAIL: kinemo studio exited with $code after SIGTERM"; exit 1; }
echo "PASS: kinemo studio served $url/ and /healthz ($health)"

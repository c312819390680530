#!/usr/bin/env bash
# The web studio in one command: an embedded stack (kinemo_allinone with the
# bundled gesture library and models, a simulated Pleo) and the studio in
# front of it, on loopback; prints the URL with its token (?token=, which
# the page turns into a cookie). Same as `kinemo studio`.
#   bash deploy/studio.sh [BUILD_DIR] [--open] [--port P] [--port-file F] ...
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="$root/build"
if [[ $# -gt 0 && "$1" != -* ]]; then build="$(realpath "$1")"; shift; fi
kinemo="$build/services/cli/kinemo"
[[ -x "$kinemo" && -x "$build/services/studio/studio" ]] ||
  { echo "studio.sh: build first: cmake --build $build --target kinemo studio kinemo_allinone pleo_sim" >&2; exit 2; }
exec "$kinemo" studio "$@"

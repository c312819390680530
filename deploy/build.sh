#!/usr/bin/env bash
# Installs the system dependencies (Debian 12) and builds kinemo (Release) in
# ./build. Re-running only rebuilds what changed.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
JOBS=${KINEMO_JOBS:-$(nproc)}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=${KINEMO_BUILD_TYPE:-Release} >/dev/null
cmake --build "$BUILD_DIR" -j "$JOBS"

#!/usr/bin/env bash
# README command 2: install dependencies, build, run every test (unit,
# service, integration) with ctest. Exit code is ctest's.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
ctest --test-dir "$BUILD_DIR" --output-on-failure -j "${KINEMO_TEST_JOBS:-2}" "$@"

#!/usr/bin/env bash
# Installs the system dependencies (Debian 12) and builds kinemo (Release) in
# ./build ($KINEMO_BUILD_DIR). Re-running only rebuilds what changed.
#
#   bash deploy/build.sh [--demo | --all] [--no-install]
#
#   --demo  README command 1: the build set of packages and only the targets
#           deploy/demo.sh runs. A new build dir is configured without tests
#           and benchmarks (GoogleTest and Google Benchmark are not needed); an
#           existing one keeps its configuration.
#   --all   (default) README command 2: every package and every target, tests
#           and benchmarks included. It reuses the build dir of --demo: the same
#           objects, more targets.
#   --no-install  skips the packages (deploy/test.sh installs them itself:
#           what the build needs first, the rest while the build runs).
#
# Prints `phase install|configure|build <seconds> s`. ccache is used when it
# is installed (CMakeLists.txt; KINEMO_CCACHE=OFF to turn it off).
set -euo pipefail
cd "$(dirname "$0")/.."
source deploy/lib/phase.sh
mode=all
install=1
for arg in "$@"; do
  case "$arg" in
    --demo) mode=demo ;;
    --all) mode=all ;;
    --no-install) install=0 ;;
    *) echo "usage: build.sh [--demo | --all] [--no-install]" >&2; exit 2 ;;
  esac
done
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
JOBS=${KINEMO_JOBS:-$(nproc)}
# What README command 1 runs (deploy/demo.sh): the CLI (kinemo runs
# kinemo-vision for cube/demo), the simulated Pleo and robot_bridge (step 5),
# the all-in-one stack `kinemo animate` starts (step 6) and the bundled store
# it is seeded from (built by running kinemo and kinemo_allinone).
DEMO_TARGETS=(kinemo kinemo-vision pleo_sim robot_bridge kinemo_allinone kinemo_seed_store)

if [[ $install -eq 1 ]]; then
  phase install
  bash deploy/install-deps.sh "--$mode"
fi

phase configure
config=(-DCMAKE_BUILD_TYPE="${KINEMO_BUILD_TYPE:-Release}")
if [[ "$mode" == all ]]; then
  config+=(-DKINEMO_BUILD_TESTS=ON -DKINEMO_BUILD_BENCHMARKS=ON)
elif [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
  config+=(-DKINEMO_BUILD_TESTS=OFF -DKINEMO_BUILD_BENCHMARKS=OFF)
fi
echo "configure: cmake in $BUILD_DIR (${config[*]})"
log=$(mktemp)
cmake -S . -B "$BUILD_DIR" -G Ninja "${config[@]}" >"$log" 2>&1 || { cat "$log" >&2; rm -f "$log"; exit 1; }
grep -E '^-- kinemo: ' "$log" || true
rm -f "$log"

phase build
targets=()
[[ "$mode" == demo ]] && targets=(--target "${DEMO_TARGETS[@]}")
echo "build: ${targets[*]:-every target} with $JOBS jobs; [done/total] before each step"
# Ninja's status line: steps done / steps of this build, and the percentage.
NINJA_STATUS="build [%f/%t %p] " cmake --build "$BUILD_DIR" -j "$JOBS" "${targets[@]}"
phase_end

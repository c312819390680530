#!/usr/bin/env bash
# README command 2: install dependencies, build, run every test (unit,
# service, integration, fuzz) with ctest. Exit code is ctest's (non-zero when
# any tier failed). Reuses the build dir of README command 1 (deploy/demo.sh):
# the same objects, the remaining targets.
#
# Prints `phase <name> <seconds> s` for install, configure, build, and each
# test tier (test-unit, test-service, test-integration, test-fuzz; test-other
# for tests in none of them). Arguments are passed to one ctest run instead
# (e.g. `bash deploy/test.sh -L planner`).
set -euo pipefail
cd "$(dirname "$0")/.."
source deploy/lib/phase.sh
t0=$(phase_now)
bash deploy/build.sh --all
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
JOBS=${KINEMO_TEST_JOBS:-2}
if [[ $# -gt 0 ]]; then
  phase test
  rc=0
  ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" "$@" || rc=$?
  phase_end
  exit $rc
fi
# Every test carries exactly one tier label (the first of its LABELS).
tiers=(unit service integration fuzz)
rc=0
summary=$(mktemp)
trap 'rm -f "$summary"' EXIT
# ctest ARGS...: one tier's run; its "N tests failed out of M" line is kept.
run_ctest() {
  local out
  out=$(mktemp)
  ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" "$@" 2>&1 | tee "$out" || rc=1
  grep -E '[0-9]+ tests failed out of [0-9]+' "$out" | tail -1 >>"$summary" || true
  rm -f "$out"
}
for tier in "${tiers[@]}"; do
  phase "test-$tier"
  echo "test: ctest -L $tier"
  run_ctest -L "^$tier\$"
done
phase test-other
others=$(ctest --test-dir "$BUILD_DIR" -N -LE "^($(IFS='|'; echo "${tiers[*]}"))\$" | grep -c '^ *Test *#' || true)
if [[ "$others" -gt 0 ]]; then
  echo "test: $others tests without a tier label"
  run_ctest -LE "^($(IFS='|'; echo "${tiers[*]}"))\$"
fi
phase_end
phase_since total "$t0"
# All tiers in one line: "tests: N passed, M failed".
awk '{for (i = 1; i <= NF; ++i) if ($i == "failed" && $(i + 1) == "out") { f += $(i - 2); n += $(i + 3) }}
     END { printf "tests: %d passed, %d failed\n", n - f, f }' "$summary"
[[ $rc -eq 0 ]] && echo "test: every tier passed" || echo "test: some tests failed (see above)" >&2
exit $rc

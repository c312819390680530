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
#
# Environment: KINEMO_BUILD_DIR (default build), KINEMO_TEST_JOBS (ctest -j,
# default 2), KINEMO_INTEGRATION_JOBS (the integration tier's -j, default
# twice KINEMO_TEST_JOBS).
set -euo pipefail
cd "$(dirname "$0")/.."
source deploy/lib/phase.sh
t0=$(phase_now)
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
JOBS=${KINEMO_TEST_JOBS:-2}
# The integration tier runs twice as many tests at once: its tests mostly wait
# (real-time streams, browsers, containers; half of 2 cores idle at -j2), and
# its heavy tests run in two lanes of one at a time (kinemo_heavy_test).
INTEGRATION_JOBS=${KINEMO_INTEGRATION_JOBS:-$((2 * JOBS))}
bg_pids=()
bg_logs=()
cleanup() {
  local p
  for p in "${bg_pids[@]}"; do kill -- "-$p" 2>/dev/null || kill "$p" 2>/dev/null || true; done
  rm -f "${bg_logs[@]}"
}
trap cleanup EXIT
# bg LOG NAME CMD...: CMD in the background, in its own process group (so
# cleanup ends it and its children), output to LOG, which ends with
# "NAME: exit <code> after <seconds> s"; sets BG_PID.
bg() {
  local log=$1 name=$2
  shift 2
  bg_logs+=("$log")
  set -m
  (
    t=$(phase_now) rc=0
    "$@" || rc=$?
    echo "$name: exit $rc after $((($(phase_now) - t) / 1000000)) s"
    exit $rc
  ) >"$log" 2>&1 &
  BG_PID=$!
  set +m
  bg_pids+=("$BG_PID")
}

# What the build needs first (the demo's packages, GoogleTest, Google
# Benchmark); the tools only the tests run (browsers, containers, clang,
# Prometheus, Praat, ...) install beside the build, mostly downloading.
phase install
bash deploy/install-deps.sh --build
tools_log=$(mktemp)
bg "$tools_log" install-deps bash deploy/install-deps.sh --all
tools_pid=$BG_PID
phase_end
bash deploy/build.sh --all --no-install
phase install-tools
echo "install-tools: waiting for the test tools' install (began with the build)"
tools_rc=0
wait "$tools_pid" || tools_rc=$?
sed 's/^/  /' "$tools_log"
if [[ $tools_rc -ne 0 ]]; then
  echo "test: installing the test tools failed (bash deploy/install-deps.sh --all)" >&2
  exit 1
fi
phase_end
if [[ $# -gt 0 ]]; then
  phase test
  rc=0
  ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" "$@" || rc=$?
  phase_end
  exit $rc
fi
# The fuzz tree (clang + sanitizers, deploy/fuzz.sh) builds while the other
# tiers run, at idle CPU priority: it takes only the CPU time the tests leave
# (the integration tier mostly waits on real-time streams, browsers and
# containers) and gives way at once when a test wants the core. The fuzz
# tier's tests wait for it (fuzz.sh's build lock), then find it built.
fuzz_log=$(mktemp)
idle=(chrt --idle 0)
"${idle[@]}" true 2>/dev/null || idle=(nice -n 19)
bg "$fuzz_log" "fuzz build" "${idle[@]}" bash deploy/fuzz.sh --build
echo "test: the fuzz tree builds in the background at idle priority (log at the fuzz tier)"
fuzz_pid=$BG_PID
# Every test carries exactly one tier label (the first of its LABELS).
tiers=(unit service integration fuzz)
rc=0
summary=$(mktemp)
bg_logs+=("$summary")
# ctest JOBS ARGS...: one tier's run; its "N tests failed out of M" line is kept.
run_ctest() {
  local out jobs=$1
  shift
  out=$(mktemp)
  ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$jobs" "$@" 2>&1 | tee "$out" || rc=1
  grep -E '[0-9]+ tests failed out of [0-9]+' "$out" | tail -1 >>"$summary" || true
  rm -f "$out"
}
for tier in "${tiers[@]}"; do
  phase "test-$tier"
  if [[ $tier == fuzz ]]; then
    # The background build's outcome; a failed or skipped one is built again
    # (or skipped) by the fuzz tests themselves, with its error shown there.
    wait "$fuzz_pid" || true
    sed 's/^/  /' "$fuzz_log"
  fi
  tier_jobs=$JOBS
  [[ $tier != integration ]] || tier_jobs=$INTEGRATION_JOBS
  echo "test: ctest -L $tier -j $tier_jobs"
  run_ctest "$tier_jobs" -L "^$tier\$"
done
phase test-other
others=$(ctest --test-dir "$BUILD_DIR" -N -LE "^($(IFS='|'; echo "${tiers[*]}"))\$" | grep -c '^ *Test *#' || true)
if [[ "$others" -gt 0 ]]; then
  echo "test: $others tests without a tier label"
  run_ctest "$JOBS" -LE "^($(IFS='|'; echo "${tiers[*]}"))\$"
fi
phase_end
phase_since total "$t0"
# All tiers in one line: "tests: N passed, M failed".
awk '{for (i = 1; i <= NF; ++i) if ($i == "failed" && $(i + 1) == "out") { f += $(i - 2); n += $(i + 3) }}
     END { printf "tests: %d passed, %d failed\n", n - f, f }' "$summary"
[[ $rc -eq 0 ]] && echo "test: every tier passed" || echo "test: some tests failed (see above)" >&2
exit $rc

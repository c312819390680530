#!/usr/bin/env bash
# Coverage-guided fuzzing of kinemo's parsers (tests/fuzz, see its README.md).
#
#   bash deploy/fuzz.sh [SECONDS] [HARNESS...]
#       Builds the fuzz build if needed (clang, ASan + UBSan, in build-fuzz or
#       $KINEMO_FUZZ_BUILD_DIR), then runs each harness (default: all) for
#       SECONDS (default 60) on one core, one after another, growing its
#       working corpus in <build>/fuzz/corpus/<name> from the committed seeds
#       in tests/fuzz/corpus/<name>. Prints one line per harness:
#         <name> runs=<N> coverage=<edges> crashes=<K>
#       Crashing inputs go to <build>/fuzz/artifacts/<name>/ (logs beside
#       them in <build>/fuzz/logs/). Exit code 1 when any harness crashed.
#   bash deploy/fuzz.sh --test SECONDS HARNESS
#       What `ctest -L fuzz` runs: the harness for SECONDS on the committed
#       corpus (regression inputs included) with a throw-away working corpus.
#       Exit 77 (skipped) where clang or libFuzzer is missing.
#   bash deploy/fuzz.sh --build
#       Only configures and builds the harnesses.
#
# Environment: KINEMO_FUZZ_BUILD_DIR, KINEMO_JOBS (build jobs, default nproc).
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${KINEMO_FUZZ_BUILD_DIR:-$ROOT/build-fuzz}
JOBS=${KINEMO_JOBS:-$(nproc)}
SKIP=2  # exit code when the toolchain is missing (77 under ctest)

mode=run
seconds=60
case "${1:-}" in
  --test) mode=test; SKIP=77; seconds=${2:?--test SECONDS HARNESS}; shift 2 ;;
  --build) mode=build; shift ;;
  -h|--help) sed -n '2,22p' "$0"; exit 0 ;;
  '') ;;
  *) if [[ "$1" =~ ^[0-9]+$ ]]; then seconds=$1; shift; fi ;;
esac
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || [ "$seconds" -lt 1 ]; then
  echo "fuzz.sh: SECONDS must be a positive integer, got '$seconds'" >&2
  exit 2
fi

# Harnesses: tests/fuzz/<name>_fuzz.cc.
all=()
for f in "$ROOT"/tests/fuzz/*_fuzz.cc; do
  n=$(basename "$f" _fuzz.cc)
  all+=("$n")
done
harnesses=("$@")
[ ${#harnesses[@]} -gt 0 ] || harnesses=("${all[@]}")
for h in "${harnesses[@]}"; do
  if [ ! -f "$ROOT/tests/fuzz/${h}_fuzz.cc" ]; then
    echo "fuzz.sh: no harness '$h' (have: ${all[*]})" >&2
    exit 2
  fi
done
[ "$mode" != test ] || [ ${#harnesses[@]} -eq 1 ] || { echo "fuzz.sh: --test takes one harness" >&2; exit 2; }

# The toolchain: clang with libFuzzer and the sanitizer runtimes
# (deploy/install-deps.sh installs clang, libclang-rt-14-dev, libfuzzer-14-dev).
probe_dir=$(mktemp -d)
trap 'rm -rf "$probe_dir"' EXIT
if ! command -v clang >/dev/null || ! command -v clang++ >/dev/null; then
  echo "fuzz.sh: clang is not installed (bash deploy/install-deps.sh)" >&2
  exit $SKIP
fi
printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' \
  >"$probe_dir/probe.cc"
if ! clang++ -fsanitize=fuzzer,address,undefined "$probe_dir/probe.cc" -o "$probe_dir/probe" 2>"$probe_dir/err"; then
  echo "fuzz.sh: clang cannot link a libFuzzer binary (libclang-rt-14-dev missing?):" >&2
  cat "$probe_dir/err" >&2
  exit $SKIP
fi

# Configure once, build incrementally; one build at a time (ctest may start
# several fuzz tests at once: the others wait here, then find it up to date).
mkdir -p "$BUILD"
exec 9>"$BUILD/.fuzz-build.lock"
flock 9
if [ ! -f "$BUILD/build.ninja" ]; then
  launcher=()
  if command -v ccache >/dev/null; then
    launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Fuzz \
    -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ "${launcher[@]}" \
    -DKINEMO_FUZZ=ON -DKINEMO_BUILD_TESTS=OFF -DKINEMO_BUILD_BENCHMARKS=OFF \
    -DKINEMO_WITH_SPHINX=OFF >"$BUILD/configure.log" 2>&1 || {
      cat "$BUILD/configure.log" >&2
      exit 2
    }
fi
if ! cmake --build "$BUILD" --target kinemo_fuzzers -j "$JOBS" >"$BUILD/build.log" 2>&1; then
  tail -n 60 "$BUILD/build.log" >&2
  echo "fuzz.sh: the fuzz build failed (log: $BUILD/build.log)" >&2
  exit 2
fi
flock -u 9
[ "$mode" != build ] || { echo "fuzz.sh: harnesses built in $BUILD/tests/fuzz"; exit 0; }

# Sanitizer reports: a stack for UBSan too; known leaks of system libraries
# (not ours) suppressed, each explained in tests/fuzz/lsan.supp.
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/tests/fuzz/lsan.supp:print_suppressions=0}

# Runs harness $1 for $2 seconds with working corpus $3, artifacts in $4,
# log $5. libFuzzer stops at a crash; the harness is restarted for the rest
# of the time (new findings only: the crashing input is not in the corpus),
# unless it crashes before its corpus is loaded (a committed input crashes).
# Sets RUNS, COVERAGE, CRASHES.
run_harness() {
  local name=$1 budget=$2 corpus=$3 artifacts=$4 log=$5
  local bin="$BUILD/tests/fuzz/${name}_fuzz"
  local seeds="$ROOT/tests/fuzz/corpus/$name"
  local dict="$ROOT/tests/fuzz/$name.dict"
  local flags=(-timeout=10 -rss_limit_mb=2560 -malloc_limit_mb=1024 -print_final_stats=1
               -use_value_profile=1 "-artifact_prefix=$artifacts/")
  [ ! -f "$dict" ] || flags+=("-dict=$dict")
  mkdir -p "$corpus" "$artifacts"
  : >"$log"
  RUNS=0 COVERAGE=0
  local start=$SECONDS attempt part rc runs cov
  for attempt in $(seq 1 20); do
    local left=$((budget - (SECONDS - start)))
    [ "$left" -ge 1 ] || break
    part="$log.$attempt"
    rc=0
    "$bin" "${flags[@]}" "-max_total_time=$left" "$corpus" "$seeds" >"$part" 2>&1 || rc=$?
    cat "$part" >>"$log"
    runs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$part" | tail -n1 | grep -o '[0-9]*$' || true)
    [ -n "$runs" ] || runs=$(grep -o '^#[0-9]*' "$part" | tail -n1 | tr -d '#' || true)
    RUNS=$((RUNS + ${runs:-0}))
    cov=$(grep -o 'cov: [0-9]*' "$part" | tail -n1 | grep -o '[0-9]*$' || true)
    [ "${cov:-0}" -le "$COVERAGE" ] || COVERAGE=$cov
    rm -f "$part"
    [ "$rc" -ne 0 ] || break
    grep -q 'INITED' "$log" || break
  done
  CRASHES=$(find "$artifacts" -maxdepth 1 -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' \
    -o -name 'oom-*' -o -name 'slow-unit-*' \) -newer "$log.start" | wc -l)
}

status=0
if [ "$mode" = test ]; then
  name=${harnesses[0]}
  work="$BUILD/fuzz/test/$name"
  rm -rf "$work"
  mkdir -p "$work/corpus" "$work/artifacts"
  touch "$work/log.start"
  run_harness "$name" "$seconds" "$work/corpus" "$work/artifacts" "$work/log"
  echo "$name runs=$RUNS coverage=$COVERAGE crashes=$CRASHES"
  if [ "$CRASHES" -gt 0 ] || ! grep -q 'INITED' "$work/log"; then
    tail -n 80 "$work/log"
    echo "fuzz.sh: $name failed; inputs in $work/artifacts (add a fixed one to tests/fuzz/corpus/$name)" >&2
    exit 1
  fi
  rm -rf "$work/corpus"
  exit 0
fi

for name in "${harnesses[@]}"; do
  mkdir -p "$BUILD/fuzz/logs"
  log="$BUILD/fuzz/logs/$name.log"
  touch "$log.start"
  run_harness "$name" "$seconds" "$BUILD/fuzz/corpus/$name" "$BUILD/fuzz/artifacts/$name" "$log"
  rm -f "$log.start"
  echo "$name runs=$RUNS coverage=$COVERAGE crashes=$CRASHES"
  [ "$CRASHES" -eq 0 ] || status=1
done
[ "$status" -eq 0 ] || echo "fuzz.sh: crashes found: see $BUILD/fuzz/artifacts/ and $BUILD/fuzz/logs/" >&2
exit $status

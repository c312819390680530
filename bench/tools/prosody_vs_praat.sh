#!/usr/bin/env bash
# Side by side, in one run, on the same files: Praat's pitch + intensity
# (praat --run, process start and file reading included) against
# `kinemo prosody FILE --json` (which also does syllables, accents, pauses and
# JSON output; process start and decoding included).
#   bench/tools/prosody_vs_praat.sh [BUILD_DIR] [AUDIO...]
#   bench/tools/prosody_vs_praat.sh AUDIO...            (BUILD_DIR = ./build)
# Each file runs REPEAT times (default 3), Praat and kinemo in turn; the
# median wall-clock and CPU (user+sys, all threads) seconds of each are
# compared. Prints one line per file and, for all files together,
#   wall_ratio R   (Praat wall / kinemo wall: how much sooner kinemo is done)
#   cpu_ratio R    (Praat CPU / kinemo CPU: how much less it computes)
# with the machine's cores and load average before and after (wall-clock
# ratios need idle cores).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
build="$root/build"
if [[ $# -gt 0 && -d "$1" ]]; then
  build="$1"
  shift
fi
repeat="${REPEAT:-3}"
kinemo="$build/services/cli/kinemo"
[[ -x "$kinemo" ]] || { echo "missing $kinemo (build target kinemo)" >&2; exit 2; }
command -v praat >/dev/null || { echo "praat is not installed" >&2; exit 2; }
files=("$@")
if [[ ${#files[@]} -eq 0 ]]; then
  shopt -s nullglob
  files=("$root"/../shared/data/speech/*/*.wav)
  [[ ${#files[@]} -gt 0 ]] || files=("$root"/tests/data/speech/*.wav)
fi
for f in "${files[@]}"; do
  [[ -f "$f" ]] || { echo "not a file: $f" >&2; exit 2; }
done
# Praat resolves relative paths against the script's folder: make them absolute.
for i in "${!files[@]}"; do files[$i]="$(realpath "${files[$i]}")"; done
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# run OUT_TIMES CMD...: appends "wall cpu" (seconds) of one run to OUT_TIMES.
run() {
  local out="$1"
  shift
  local t0 t1
  t0=$(date +%s%N)
  /usr/bin/time -f "%U %S" -o "$tmp/cpu" "$@" >/dev/null 2>"$tmp/err" || { cat "$tmp/err" >&2; exit 1; }
  t1=$(date +%s%N)
  awk -v a="$t0" -v b="$t1" '{printf "%.4f %.3f\n", (b - a) / 1e9, $1 + $2}' "$tmp/cpu" >>"$out"
}
median() {  # median of column $2 of file $1
  sort -g -k"$2,$2" "$1" | awk -v c="$2" '{v[NR] = $c} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'
}
echo "machine: $(nproc) cores, load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
total_audio=0 pw=0 pc=0 kw=0 kc=0
for f in "${files[@]}"; do
  dur=$("$kinemo" audio info "$f" --json | python3 -c "import json,sys;print(json.load(sys.stdin)['duration_s'])")
  : >"$tmp/praat"
  : >"$tmp/kinemo"
  for ((r = 0; r < repeat; ++r)); do
    run "$tmp/praat" praat --run "$here/praat_pitch_intensity.praat" "$f"
    run "$tmp/kinemo" "$kinemo" prosody "$f" --json
  done
  p_wall=$(median "$tmp/praat" 1) p_cpu=$(median "$tmp/praat" 2)
  k_wall=$(median "$tmp/kinemo" 1) k_cpu=$(median "$tmp/kinemo" 2)
  printf '%-40s %7.2f s audio  praat %.3f s wall %.3f s CPU  kinemo %.3f s wall %.3f s CPU\n' \
    "$(basename "$f")" "$dur" "$p_wall" "$p_cpu" "$k_wall" "$k_cpu"
  read -r total_audio pw pc kw kc < <(awk -v a="$total_audio" -v b="$dur" -v pw="$pw" -v pc="$pc" -v kw="$kw" -v kc="$kc" \
    -v w1="$p_wall" -v c1="$p_cpu" -v w2="$k_wall" -v c2="$k_cpu" 'BEGIN{print a+b, pw+w1, pc+c1, kw+w2, kc+c2}')
done
echo "machine: load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
awk -v a="$total_audio" -v pw="$pw" -v pc="$pc" -v kw="$kw" -v kc="$kc" 'BEGIN{
  printf "total %.1f s audio: praat %.3f s wall, %.3f s CPU; kinemo %.3f s wall, %.3f s CPU (%.0fx real time)\n",
    a, pw, pc, kw, kc, a / (kw > 0 ? kw : 1e-9)
  printf "wall_ratio %.2f\n", pw / (kw > 0 ? kw : 1e-9)
  printf "cpu_ratio %.2f\n", pc / (kc > 0 ? kc : 1e-9)}'

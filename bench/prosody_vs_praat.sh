#!/usr/bin/env bash
# Side by side, in one run, on the same files: Praat's pitch + intensity
# (praat --run, process start and file reading included) against
# `kinemo prosody FILE --json` (which also does syllables, accents, pauses and
# JSON output; process start and decoding included). CPU seconds (user+sys).
#   bench/prosody_vs_praat.sh [BUILD_DIR] [AUDIO...]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
build="${1:-$root/build}"
shift || true
kinemo="$build/services/cli/kinemo"
[[ -x "$kinemo" ]] || { echo "missing $kinemo (build target kinemo)" >&2; exit 2; }
command -v praat >/dev/null || { echo "praat is not installed" >&2; exit 2; }
files=("$@")
if [[ ${#files[@]} -eq 0 ]]; then
  shopt -s nullglob
  files=("$root"/../shared/data/speech/*/*.wav)
  [[ ${#files[@]} -gt 0 ]] || files=("$root"/tests/data/speech/*.wav)
fi
cpu() {  # prints user+sys CPU seconds of the command
  local t
  t=$( { /usr/bin/time -f "%U %S" "$@" >/dev/null 2>/dev/null; } 2>&1 | tail -1)
  awk '{print $1 + $2}' <<<"$t"
}
total_audio=0 total_praat=0 total_kinemo=0
# Praat resolves relative paths against the script's folder: make them absolute.
for i in "${!files[@]}"; do files[$i]="$(realpath "${files[$i]}")"; done
for f in "${files[@]}"; do
  dur=$(soxi -D "$f" 2>/dev/null || python3 -c "import wave,sys;w=wave.open(sys.argv[1]);print(w.getnframes()/w.getframerate())" "$f")
  p=$( { /usr/bin/time -f "%U %S" praat --run "$here/praat_pitch_intensity.praat" "$f" >/dev/null; } 2>&1 | tail -1 | awk '{print $1+$2}')
  k=$( { /usr/bin/time -f "%U %S" "$kinemo" prosody "$f" --json >/dev/null; } 2>&1 | tail -1 | awk '{print $1+$2}')
  printf '%-50s %7.2f s audio  praat %6.3f s  kinemo %6.3f s\n' "$(basename "$f")" "$dur" "$p" "$k"
  total_audio=$(awk -v a="$total_audio" -v b="$dur" 'BEGIN{print a+b}')
  total_praat=$(awk -v a="$total_praat" -v b="$p" 'BEGIN{print a+b}')
  total_kinemo=$(awk -v a="$total_kinemo" -v b="$k" 'BEGIN{print a+b}')
done
awk -v a="$total_audio" -v p="$total_praat" -v k="$total_kinemo" 'BEGIN{
  printf "total %.1f s audio: praat %.3f s CPU (%.0fx real time), kinemo %.3f s CPU (%.0fx real time), kinemo/praat speed %.1fx\n",
    a, p, a/(p>0?p:1e-9), k, a/(k>0?k:1e-9), p/(k>0?k:1e-9)}'

#!/usr/bin/env bash
# Agreement of kinemo's pitch and intensity with Praat's, frame by frame.
#   bench/tools/praat_compare.sh [BUILD_DIR] [AUDIO...]
# Without AUDIO: every WAV in tests/data/speech and ../shared/data/speech
# (when present). Needs `praat` (Debian package) and the prosody_praat_compare
# tool (cmake --build BUILD_DIR --target prosody_praat_compare).
# Prints one JSON line per file and a pooled summary.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
build="${1:-$root/build}"
shift || true
tool="$build/bench/tools/prosody_praat_compare"
[[ -x "$tool" ]] || { echo "missing $tool (build target prosody_praat_compare)" >&2; exit 2; }
command -v praat >/dev/null || { echo "praat is not installed" >&2; exit 2; }
files=("$@")
if [[ ${#files[@]} -eq 0 ]]; then
  shopt -s nullglob
  files=("$root"/tests/data/speech/*.wav "$root"/../shared/data/speech/*/*.wav)
fi
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Praat resolves relative paths against the script's folder: make them absolute.
for i in "${!files[@]}"; do files[$i]="$(realpath "${files[$i]}")"; done
for f in "${files[@]}"; do
  praat --run "$here/praat_reference.praat" "$f" "$tmp/p.csv" "$tmp/i.csv"
  "$tool" "$f" "$tmp/p.csv" "$tmp/i.csv"
done | tee "$tmp/all.jsonl"
python3 - "$tmp/all.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
vb = sum(r["voiced_both"] for r in rows)
f0 = sum(r["f0_within_50_cents"] * r["voiced_both"] for r in rows) / max(vb, 1)
pf = sum(r["pitch_frames"] for r in rows)
va = sum(r["voicing_agreement"] * r["pitch_frames"] for r in rows) / max(pf, 1)
inf = sum(r["intensity_frames"] for r in rows)
it = sum(r["intensity_within_1db"] * r["intensity_frames"] for r in rows) / max(inf, 1)
print(json.dumps({"files": len(rows), "pitch_frames": pf, "f0_within_50_cents": round(f0, 4),
                  "voicing_agreement": round(va, 4), "intensity_within_1db": round(it, 4)}))
PY

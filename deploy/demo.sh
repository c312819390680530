#!/usr/bin/env bash
# README command 1: install dependencies, build, and run the main job on the
# bundled sample data (no Docker, no running services needed). Outputs go to
# ./out (override with KINEMO_OUT).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
BUILD_DIR=${KINEMO_BUILD_DIR:-build}
OUT=${KINEMO_OUT:-out}
mkdir -p "$OUT"
K="$BUILD_DIR/services/cli/kinemo"
DATA=tests/data

echo "== motion: the bundled clips"
for f in "$DATA"/motion/*.bvh; do
  "$K" bvh info "$f"
done
echo
echo "== motion: resample the 120 fps CMU clip to 30 fps and write BVH"
"$K" bvh convert "$DATA/motion/131_01.bvh" "$OUT/131_01_30fps.bvh" --fps 30
"$K" bvh info "$OUT/131_01_30fps.bvh"
echo
echo "== speech: the bundled recordings"
for f in "$DATA"/speech/*.wav; do
  "$K" audio info "$f"
done
echo
echo "demo outputs in $OUT/"

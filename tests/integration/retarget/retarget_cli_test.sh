#!/usr/bin/env bash
# kinemo retarget IN.bvh --to RIG.glb -o OUT.glb|OUT.bvh [--map MAP.json] [--json]
#   retarget_cli_test.sh cli|validator SOURCE_DIR BUILD_DIR
#   cli:       JSON report, GLB and BVH outputs, errors (exit 2, named)
#   validator: the GLBs pass the Khronos glTF validator with 0 errors
set -euo pipefail
mode="$1"; src="$2"; build="$3"
kinemo="$build/services/cli/kinemo"
data="$src/tests/data"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

field() { python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))[sys.argv[2]]; print(len(v) if isinstance(v, list) else v)' "$1" "$2"; }

smplx="$data/paired/beat2/2_scott_0_1_1.bvh"
bandai="$data/motion/dataset-1_bye_normal_001.bvh"
man="$data/characters/quaternius_man_casual.glb"
woman="$data/characters/quaternius_woman_casual.glb"
robot="$data/characters/robot_expressive.glb"

if [[ "$mode" == cli ]]; then
  "$kinemo" retarget "$smplx" --to "$man" -o "$tmp/man.glb" --json >"$tmp/r.json"
  for k in mapped_roles unmapped_roles frames root_scale seconds; do
    python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); assert sys.argv[2] in d' "$tmp/r.json" "$k" ||
      fail "no $k in $(cat "$tmp/r.json")"
  done
  [[ "$(field "$tmp/r.json" frames)" == 1906 ]] || fail "frames: $(cat "$tmp/r.json")"
  (( $(field "$tmp/r.json" mapped_roles) >= 40 )) || fail "mapped roles: $(cat "$tmp/r.json")"
  grep -q '"left_upper_arm"' "$tmp/r.json" || fail "left_upper_arm not mapped"
  [[ -s "$tmp/man.glb" ]] && [[ "$(head -c 4 "$tmp/man.glb")" == glTF ]] || fail "no GLB written"
  # BVH on the character's skeleton, readable by kinemo bvh info.
  "$kinemo" retarget "$bandai" --to "$woman" -o "$tmp/woman.bvh" >"$tmp/text.log"
  grep -q 'bandai' "$tmp/text.log" || fail "text summary: $(cat "$tmp/text.log")"
  "$kinemo" bvh info "$tmp/woman.bvh" --json >"$tmp/info.json"
  [[ "$(field "$tmp/info.json" num_frames)" == 111 ]] || fail "BVH frames: $(cat "$tmp/info.json" | head -c 300)"
  # Onto a BVH skeleton (the SMPL-X take's own): BVH out; GLB out is refused.
  "$kinemo" retarget "$bandai" --to "$smplx" -o "$tmp/smplx.bvh" --json >"$tmp/s.json"
  code=0; "$kinemo" retarget "$bandai" --to "$smplx" -o "$tmp/x.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- '-o: a GLB needs a glTF/VRM rig (--to)' "$tmp/err" || fail "GLB onto a BVH rig: exit $code: $(cat "$tmp/err")"
  # The spelling is -o/--out; --output still works for a release, with a note.
  "$kinemo" retarget "$bandai" --to "$woman" --out "$tmp/out.bvh" >/dev/null 2>"$tmp/err" || fail "--out: $(cat "$tmp/err")"
  [[ -s "$tmp/out.bvh" && ! -s "$tmp/err" ]] || fail "--out: $(cat "$tmp/err")"
  "$kinemo" retarget "$bandai" --to "$woman" --output "$tmp/old.bvh" >/dev/null 2>"$tmp/err" || fail "--output: $(cat "$tmp/err")"
  [[ -s "$tmp/old.bvh" ]] && grep -q -- '--output is deprecated.*use --out' "$tmp/err" || fail "--output: $(cat "$tmp/err")"
  code=0; "$kinemo" retarget "$bandai" --to "$woman" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- '-o/--out is required' "$tmp/err" || fail "no output: exit $code: $(cat "$tmp/err")"
  # A map that leaves required roles out: exit 2 naming them.
  echo '{"hips": "Hips", "head": "Head", "spine": "Abdomen"}' >"$tmp/map.json"
  code=0; "$kinemo" retarget "$smplx" --to "$man" --map "$tmp/map.json" -o "$tmp/y.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q 'left_upper_arm' "$tmp/err" && grep -q 'right_shin' "$tmp/err" ||
    fail "incomplete map: exit $code: $(cat "$tmp/err")"
  # Missing input / rig: exit 2, the option named.
  code=0; "$kinemo" retarget "$tmp/none.bvh" --to "$man" -o "$tmp/z.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q 'input' "$tmp/err" || fail "missing input: exit $code: $(cat "$tmp/err")"
  code=0; "$kinemo" retarget "$smplx" --to "$tmp/none.glb" -o "$tmp/z.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- '--to' "$tmp/err" || fail "missing rig: exit $code: $(cat "$tmp/err")"
  [[ ! -e "$tmp/z.glb" && ! -e "$tmp/y.glb" ]] || fail "a failed run wrote an output"
  echo "PASS: kinemo retarget: $(cat "$tmp/r.json" | python3 -c 'import json,sys; d=json.load(sys.stdin); print({k: d[k] for k in ("frames","root_scale","seconds")}, len(d["mapped_roles"]), "roles")')"
  exit 0
fi

# validator
command -v npm >/dev/null && command -v node >/dev/null || { echo "SKIP: npm/node not installed"; exit 77; }
tools="$build/test-tools/gltf-validator"
if [[ ! -f "$tools/node_modules/gltf-validator/package.json" ]]; then
  mkdir -p "$tools"
  npm install --prefix "$tools" --no-audit --no-fund --silent gltf-validator >"$tmp/npm.log" 2>&1 ||
    { echo "SKIP: npm install gltf-validator failed:"; tail -5 "$tmp/npm.log"; exit 77; }
fi
"$kinemo" retarget "$smplx" --to "$man" -o "$tmp/man.glb"
"$kinemo" retarget "$bandai" --to "$woman" -o "$tmp/woman.glb"
"$kinemo" retarget "$smplx" --to "$robot" -o "$tmp/robot.glb"
cat >"$tmp/validate.js" <<'JS'
const fs = require('fs');
const validator = require(process.argv[2] + '/node_modules/gltf-validator');
(async () => {
  let errors = 0;
  for (const file of process.argv.slice(3)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)));
    const i = report.issues;
    console.log(`${file.split('/').pop()}: ${i.numErrors} errors, ${i.numWarnings} warnings, ` +
                `${report.info.animationCount} animations, validator ${report.validatorVersion}`);
    for (const m of i.messages.filter(m => m.severity === 0).slice(0, 10)) console.log(`  ${m.code} ${m.pointer}: ${m.message}`);
    errors += i.numErrors;
  }
  process.exit(0);
})().catch(e => { console.error(e); process.exit(2); });
JS
node "$tmp/validate.js" "$tools" "$tmp/man.glb" "$tmp/woman.glb" "$tmp/robot.glb" "$robot" | tee "$tmp/report.txt"
errors() { grep "^$1: " "$tmp/report.txt" | sed -E 's/^[^:]*: ([0-9]+) errors.*/\1/'; }
[[ "$(errors man.glb)" == 0 && "$(errors woman.glb)" == 0 ]] || fail "the glTF validator found errors"
# robot_expressive.glb itself has 752 errors (non-normalised skin weights in
# its meshes); the animated GLB must add none.
[[ "$(errors robot.glb)" == "$(errors robot_expressive.glb)" ]] || fail "retargeting added validator errors to the robot"
echo "PASS: 0 validator errors (the robot: only its own)"

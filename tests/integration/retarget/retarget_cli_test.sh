#!/usr/bin/env bash
# kinemo retarget IN.bvh --to RIG.glb -o OUT.glb|OUT.bvh [--map MAP.json] [--visemes V.json] [--json]
# kinemo rig info RIG --json
#   retarget_cli_test.sh cli|face|validator|blender|fbx|vrma SOURCE_DIR BUILD_DIR
#   cli:       JSON report, GLB and BVH outputs, errors (exit 2, named)
#   face:      rig info of every character; the face of BEAT2 take 2_2 (its
#              forced-aligned phones as OVR visemes, its captured jaw) onto
#              the VALID man, Godette, the VRM 1.0 model and the SMPL-X jaw
#   validator: the GLBs (faces, compressed inputs, VRM) pass the Khronos glTF
#              validator with 0 errors
#   blender:   Blender's glTF importer reads the GLBs written for the VALID man
#              and Godette (kinemo animate --rig on real speech, and retarget
#              --visemes): shape keys with changing fcurves, a moving armature
#   fbx:       FBX rigs (the Quaternius man as Blender's FBX exporter wrote
#              it, with Mixamo names; Character Creator names, skeleton
#              alone): rig info names the format, retarget writes GLB, BVH and
#              FBX with the facing and feet of the GLB rig, bad options exit 2
#              naming them; animate --rig RIG.fbx on real speech (when
#              kinemo_allinone is built); Blender's own FBX importer reads the FBX with the
#              motion of the BVH (the right hand within 1 mm at five frames;
#              skips with 77 without blender)
#   vrma:      VRM Animations (-o OUT.vrma) of take 2_2 with its face onto
#              Godette (VRM 0.x) and the VRM 1.0 model, read by three.js with
#              @pixiv/three-vrm-animation (tests/tools/vrma_check, npm, from
#              its lock file): the hands, feet and head posed from what the
#              plugin read match the BVH of the same retarget within 2 mm,
#              Godette's vowels move; a rig that is no VRM is refused naming -o;
#              Godette's VRMA as the input onto the man (facing, feet), a GLB
#              named .vrma refused naming the input
set -euo pipefail
mode="$1"; src="$2"; build="$3"
kinemo="$build/services/cli/kinemo"
data="$src/tests/data"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

field() { python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))[sys.argv[2]]; print(len(v) if isinstance(v, list) else v)' "$1" "$2"; }

smplx="$data/paired/beat2/2_scott_0_1_1.bvh"
take2="$data/paired/beat2/2_scott_0_2_2"
valid="$data/characters/valid_white_m_1_casual.glb"
godette="$data/characters/godette.vrm"
vrm1="$data/characters/formats/vrm1_expressions_test.vrm"
speech="$data/speech/sense_and_sensibility_01_austen_64kb-0870.wav"
here="$(cd "$(dirname "$0")" && pwd)"
# The face of take 2_2 as a viseme file (beat2_face.py).
face_file() { python3 "$here/beat2_face.py" "$take2.bvh" "$take2.TextGrid" "$tmp/face.json"; }
json_get() { python3 -c 'import json,sys; d=json.loads(open(sys.argv[1]).read().strip().split("\n")[-1]); print(eval(sys.argv[2], {"d": d}))' "$1" "$2"; }
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
  [[ $code == 2 ]] && grep -q -- '-o: a GLB needs a glTF/VRM/FBX rig (--to)' "$tmp/err" || fail "GLB onto a BVH rig: exit $code: $(cat "$tmp/err")"
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

if [[ "$mode" == face ]]; then
  # rig info: the format, the mouth family and the driven face channels.
  for spec in "$valid:glb:rocketbox:49" "$godette:vrm0:vrm0:10" "$vrm1:vrm1::2" "$robot:glb::3" "$man:glb::0" \
              "$data/characters/formats/quaternius_man_draco.glb:glb::0"; do
    IFS=: read -r file format mouth driven <<<"$spec"
    "$kinemo" rig info "$file" --json >"$tmp/info.json" || fail "rig info $file"
    [[ "$(json_get "$tmp/info.json" 'd["format"]')" == "$format" ]] || fail "$file: format $(head -c 200 "$tmp/info.json")"
    [[ "$(json_get "$tmp/info.json" 'd["mouth_family"]')" == "$mouth" ]] || fail "$file: mouth family"
    [[ "$(json_get "$tmp/info.json" 'd["face_channels_driven"]')" == "$driven" ]] || fail "$file: driven face channels"
  done
  [[ "$(json_get "$tmp/info.json" 'd["compression"]')" == "['KHR_draco_mesh_compression']" ]] || fail "draco not reported"
  [[ "$(json_get "$tmp/info.json" 'd["vowel_open_deg"]')" == "2.65" ]] || fail "rig info: vowel_open_deg"
  "$kinemo" rig info "$valid" >"$tmp/info.txt"
  grep -q 'h_teeth.t_AE_AA_h *follows h_expressions.AE_AA_h' "$tmp/info.txt" || fail "text rig info: $(head -20 "$tmp/info.txt")"
  grep -q 'vowels open with the jaw, full at 2.65 deg' "$tmp/info.txt" || fail "text rig info: no vowel opening line"
  face_file
  # The VALID man: 13 visemes, MouthOpen, eyes, brows, expressions and their teeth.
  "$kinemo" retarget "$take2.bvh" --to "$valid" --visemes "$tmp/face.json" -o "$tmp/valid.glb" --json >"$tmp/v.json"
  [[ "$(json_get "$tmp/v.json" 'd["face_frames"]')" == 1804 ]] || fail "face frames: $(head -c 300 "$tmp/v.json")"
  [[ "$(json_get "$tmp/v.json" 'd["morph_weights_written"]')" == 96 ]] || fail "VALID morph weights"
  [[ "$(json_get "$tmp/v.json" 'len(d["face_channels_mapped"])')" == 49 ]] || fail "VALID channels"
  grep -q '"H_DDS_HighRes/h_expressions.MPB_Up_h"' "$tmp/v.json" || fail "VALID: MPB not mapped"
  # Godette: the VRM 0.x presets; the VRM 1.0 model: its expressions (no morphs to write).
  "$kinemo" retarget "$take2.bvh" --to "$godette" --visemes "$tmp/face.json" -o "$tmp/godette.glb" --json >"$tmp/g.json"
  [[ "$(json_get "$tmp/g.json" 'd["face_channels_mapped"][:5]')" == "['a', 'i', 'u', 'e', 'o']" ]] || fail "Godette channels"
  [[ "$(json_get "$tmp/g.json" 'd["morph_weights_written"]')" == 15 ]] || fail "Godette morph weights"
  "$kinemo" retarget "$take2.bvh" --to "$vrm1" --visemes "$tmp/face.json" -o "$tmp/vrm1.glb" --json >"$tmp/1.json"
  [[ "$(json_get "$tmp/1.json" 'd["target_format"]')" == vrm1 ]] || fail "vrm1 format"
  python3 - "$tmp/1.json" <<'PY' || fail "VRM 1.0: facing/feet: $(head -c 400 "$tmp/1.json")"
import json, sys
d = json.load(open(sys.argv[1]))
axes = max(max(v["up"], v["forward"]) for v in d["facing_p95_deg"].values() if isinstance(v, dict))
assert axes <= 5 and d["facing_p95_deg"]["shoulder_left"] <= 5, d["facing_p95_deg"]
assert d["foot_slide_p95_m_s"] <= 0.01, d["foot_slide_p95_m_s"]
PY
  # The SMPL-X skeleton has a jaw: its channel is the face's jaw (closed on B/P/M).
  "$kinemo" retarget "$take2.bvh" --to "$take2.bvh" --visemes "$tmp/face.json" -o "$tmp/smplx.bvh" --json >"$tmp/s.json"
  [[ "$(json_get "$tmp/s.json" 'd["jaw_bone"]')" == jaw ]] || fail "SMPL-X jaw"
  python3 - "$here/beat2_face.py" "$tmp/smplx.bvh" "$tmp/face.json" <<'PY' || fail "the BVH jaw is not the face's"
import json, sys
sys.argv = ["x"] + sys.argv[1:]
exec(open(sys.argv[1]).read().split("def main")[0])
_, jaw = jaw_track(sys.argv[2])
want = [f["jaw_deg"] * (1 - f["ovr"][1]) for f in json.load(open(sys.argv[3]))["frames"]]
worst = max(abs(a - b) for a, b in zip(jaw, want))
assert len(jaw) == len(want) and worst < 0.01, worst
PY
  # Errors: a missing or malformed viseme file, exit 2 naming --visemes.
  code=0; "$kinemo" retarget "$take2.bvh" --to "$valid" --visemes "$tmp/none.json" -o "$tmp/x.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- '--visemes' "$tmp/err" || fail "missing visemes: exit $code: $(cat "$tmp/err")"
  echo '{"frame_time_s": 0.0333, "frames": [{"time_s": 0, "weights": [2]}]}' >"$tmp/bad.json"
  code=0; "$kinemo" retarget "$take2.bvh" --to "$valid" --visemes "$tmp/bad.json" -o "$tmp/x.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- '--visemes' "$tmp/err" || fail "bad visemes: exit $code: $(cat "$tmp/err")"
  echo '{"controls": [{"morph": "Nose", "drive": {"aa": 1}}]}' >"$tmp/map.json"
  code=0; "$kinemo" retarget "$take2.bvh" --to "$valid" --face-map "$tmp/map.json" -o "$tmp/x.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q 'controls\[0\].morph' "$tmp/err" || fail "bad face map: exit $code: $(cat "$tmp/err")"
  [[ ! -e "$tmp/x.glb" ]] || fail "a failed run wrote an output"
  echo "PASS: faces on VALID ($(json_get "$tmp/v.json" 'len(d["face_channels_mapped"])') channels), Godette, VRM 1.0, SMPL-X jaw"
  exit 0
fi

if [[ "$mode" == fbx ]]; then
  mixamo="$data/characters/formats/quaternius_man_mixamo.fbx"
  cc="$data/characters/formats/quaternius_man_cc_armature.fbx"
  "$kinemo" rig info "$mixamo" --json >"$tmp/info.json"
  [[ "$(json_get "$tmp/info.json" 'd["format"], d["family"]')" == "('fbx', 'mixamo')" ]] ||
    fail "rig info: $(head -c 300 "$tmp/info.json")"
  "$kinemo" rig info "$cc" --json >"$tmp/info.json"
  [[ "$(json_get "$tmp/info.json" 'd["format"], d["family"], len(d["mapped_roles"])')" == "('fbx', 'cmu_iclone', 48)" ]] ||
    fail "rig info (CC names, no mesh): $(head -c 300 "$tmp/info.json")"
  for out in glb bvh fbx; do
    "$kinemo" retarget "$take2.bvh" --to "$mixamo" -o "$tmp/m.$out" --json >"$tmp/$out.json"
    [[ -s "$tmp/m.$out" ]] || fail "no $out written"
    # Trunk and head axes p95 <= 1 deg, shoulder line <= 5, feet <= 0.01 m/s.
    [[ "$(json_get "$tmp/$out.json" 'd["target_format"], d["frames"], max(max(v["up"], v["forward"]) for v in d["facing_p95_deg"].values() if isinstance(v, dict)) <= 1, d["facing_p95_deg"]["shoulder_left"] <= 5, d["foot_slide_p95_m_s"] <= 0.01')" == "('fbx', 1804, True, True, True)" ]] ||
      fail "retarget -o $out: $(head -c 600 "$tmp/$out.json")"
  done
  [[ "$(head -c 18 "$tmp/m.fbx")" == "Kaydara FBX Binary" ]] || fail "not a binary FBX"
  "$kinemo" retarget "$take2.bvh" --to "$cc" -o "$tmp/cc.bvh" --json >"$tmp/cc.json"
  # FBX output needs an FBX rig; a truncated FBX is refused naming the file.
  code=0; "$kinemo" retarget "$take2.bvh" --to "$man" -o "$tmp/x.fbx" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- 'an FBX needs an FBX rig' "$tmp/err" || fail "FBX from a GLB rig: exit $code: $(cat "$tmp/err")"
  head -c 30000 "$mixamo" >"$tmp/cut.fbx"
  code=0; "$kinemo" retarget "$take2.bvh" --to "$tmp/cut.fbx" -o "$tmp/x.glb" 2>"$tmp/err" || code=$?
  [[ $code == 2 ]] && grep -q -- "cut.fbx" "$tmp/err" || fail "truncated FBX: exit $code: $(cat "$tmp/err")"
  [[ ! -e "$tmp/x.glb" ]] || fail "a refused retarget wrote its output"
  # kinemo animate --rig RIG.fbx on real speech (the embedded stack), when it is built.
  if [[ -x "$build/services/allinone/kinemo_allinone" ]]; then
    "$kinemo" animate "$speech" --embedded --rig "$mixamo" -o "$tmp/speech.glb" --json >"$tmp/a.json"
    [[ "$(head -c 4 "$tmp/speech.glb")" == glTF ]] || fail "animate --rig FBX: no GLB"
    [[ "$(json_get "$tmp/a.json" 'd["target_format"], d["frames"] > 100')" == "('fbx', True)" ]] ||
      fail "animate --rig FBX: $(tail -c 400 "$tmp/a.json")"
    "$kinemo" animate "$speech" --embedded --rig "$mixamo" -o "$tmp/speech.fbx" >/dev/null
    [[ "$(head -c 18 "$tmp/speech.fbx")" == "Kaydara FBX Binary" ]] || fail "animate --rig FBX -o FBX: not an FBX"
  else
    echo "note: kinemo_allinone not built: animate --rig not run"
  fi
  command -v blender >/dev/null || { echo "SKIP: blender not installed (deploy/install-deps.sh)"; exit 77; }
  blender -b --factory-startup --python "$here/blender_fbx.py" -- "$tmp/m.fbx" "$tmp/m.bvh" \
    mixamorig:RightHand 0,100,500,1000,1803 >"$tmp/blender.log" 2>&1 || true
  grep '^KINEMO_BLENDER ' "$tmp/blender.log" | sed 's/^KINEMO_BLENDER //' >"$tmp/b.json"
  [[ -s "$tmp/b.json" ]] || fail "blender: $(tail -20 "$tmp/blender.log")"
  echo "blender: $(json_get "$tmp/b.json" 'd["error"] or (d["max_distance_m"], d["skinned_meshes"], d["fbx_frames"])')"
  [[ "$(json_get "$tmp/b.json" 'd["error"] == "" and d["max_distance_m"] < 0.001 and d["skinned_meshes"] >= 4 and d["fbx_frames"][1] > 1800')" == True ]] ||
    fail "Blender's FBX import: $(cat "$tmp/b.json")"
  echo "PASS: FBX rigs in (Mixamo, CC names), GLB/BVH/FBX out; Blender imports the FBX with the BVH's motion"
  exit 0
fi

if [[ "$mode" == vrma ]]; then
  command -v node >/dev/null || { echo "SKIP: node is not installed (deploy/install-deps.sh --all)"; exit 77; }
  # three.js and three-vrm-animation from the committed lock: installed by
  # deploy/install-deps.sh --all into the tool's folder; else here, into a copy.
  tool="$src/tests/tools/vrma_check"
  if [[ ! -d "$tool/node_modules/@pixiv/three-vrm-animation" ]]; then
    cp "$tool/package.json" "$tool/package-lock.json" "$tool/check.mjs" "$tmp/"
    tool="$tmp"
    (cd "$tool" && npm ci --omit=optional --no-audit --no-fund --loglevel=error >npm.log 2>&1) || {
      echo "SKIP: npm ci of the VRMA check failed (registry unreachable?)"; tail -5 "$tool/npm.log"; exit 77; }
  fi
  face_file
  for rig in "$godette" "$vrm1"; do
    name="$(basename "$rig" .vrm)"
    "$kinemo" retarget "$take2.bvh" --to "$rig" --visemes "$tmp/face.json" -o "$tmp/$name.vrma" --json >"$tmp/$name.json"
    "$kinemo" retarget "$take2.bvh" --to "$rig" --visemes "$tmp/face.json" -o "$tmp/$name.bvh" >/dev/null
    [[ "$(head -c 4 "$tmp/$name.vrma")" == glTF ]] || fail "$name.vrma is no GLB"
    node "$tool/check.mjs" --vrma "$tmp/$name.vrma" --bvh "$tmp/$name.bvh" --vrm "$rig" | tee "$tmp/$name.check"
    echo "$name: $(json_get "$tmp/$name.json" 'd["expressions_written"]') expressions written"
  done
  python3 - "$tmp/godette.check" "$tmp/godette.json" <<'PY' || fail "Godette's VRMA"
import json, sys
c = json.load(open(sys.argv[1]))
r = json.loads(open(sys.argv[2]).read().strip().split("\n")[-1])
assert c["bones"] >= 45, c["bones"]  # Godette's humanoid: 45 bones, the thumbs' three each
assert r["expressions_written"] == 10, r
# The vowels open and close with the speech: aa fully open at its widest, shut between.
for v in ("aa", "ih", "ou", "ee", "oh"):
    p = c["presets"][v]
    assert p["min"] == 0 and p["max"] > 0.5 and p["rises"] >= 10, (v, p)
PY
  # A VRM Animation as the input: Godette's file onto the man (a GLB, no VRM).
  "$kinemo" retarget "$tmp/godette.vrma" --to "$man" -o "$tmp/man_from_vrma.glb" --json >"$tmp/from.json"
  python3 - "$tmp/from.json" <<'PY' || fail "a VRMA as the input: $(tail -c 600 "$tmp/from.json")"
import json, sys
d = json.loads(open(sys.argv[1]).read().strip().split("\n")[-1])
assert d["frames"] == 1804, d["frames"]  # take 2_2 at 30 fps, every frame of the file
assert len(d["mapped_roles"]) >= 40 and "left_upper_arm" in d["mapped_roles"], d["mapped_roles"]
assert max(v for k, v in d["facing_p95_deg"]["hips"].items()) < 5, d["facing_p95_deg"]
assert d["min_foot_height_m"] > -0.02, d["min_foot_height_m"]
print(f"  godette.vrma -> the man: {d['frames']} frames, {len(d['mapped_roles'])} roles, hips facing within "
      f"{max(d['facing_p95_deg']['hips'].values()):.2g} deg")
PY
  "$kinemo" retarget "$take2.bvh" --to "$man" -o "$tmp/not_an_animation.glb" >/dev/null
  mv "$tmp/not_an_animation.glb" "$tmp/not_an_animation.vrma"
  set +e
  "$kinemo" retarget "$tmp/not_an_animation.vrma" --to "$man" -o "$tmp/x.glb" 2>"$tmp/err3.txt"; rc3=$?
  set -e
  [[ $rc3 == 2 ]] && grep -q "input: .*not a VRM Animation" "$tmp/err3.txt" || fail "a GLB named .vrma: rc $rc3, $(cat "$tmp/err3.txt")"
  # Only a VRM character has the humanoid a VRM Animation names.
  set +e
  "$kinemo" retarget "$take2.bvh" --to "$man" -o "$tmp/man.vrma" 2>"$tmp/err.txt"; rc=$?
  "$kinemo" retarget "$take2.bvh" --to "$take2.bvh" -o "$tmp/bvh.vrma" 2>"$tmp/err2.txt"; rc2=$?
  set -e
  [[ $rc == 2 ]] && grep -q "not a VRM" "$tmp/err.txt" || fail "a GLB that is no VRM: rc $rc, $(cat "$tmp/err.txt")"
  [[ $rc2 == 2 ]] && grep -q -- "-o.*VRM character" "$tmp/err2.txt" || fail "a BVH rig: rc $rc2, $(cat "$tmp/err2.txt")"
  [[ ! -e "$tmp/man.vrma" ]] || fail "a refused VRMA was written"
  echo "PASS: VRMAs for Godette (VRM 0.x) and the VRM 1.0 model read by three-vrm-animation match the BVH; no VRMA from a GLB or BVH rig"
  exit 0
fi

if [[ "$mode" == blender ]]; then
  command -v blender >/dev/null || { echo "SKIP: blender not installed (deploy/install-deps.sh)"; exit 77; }
  face_file
  outs=()
  "$kinemo" retarget "$take2.bvh" --to "$valid" --visemes "$tmp/face.json" -o "$tmp/valid_beat2.glb" >/dev/null
  "$kinemo" retarget "$take2.bvh" --to "$godette" --visemes "$tmp/face.json" -o "$tmp/godette_beat2.glb" >/dev/null
  outs+=("$tmp/valid_beat2.glb" "$tmp/godette_beat2.glb")
  # kinemo animate --rig on real speech (the embedded stack), when it is built.
  if [[ -x "$build/services/allinone/kinemo_allinone" ]]; then
    "$kinemo" animate "$speech" --embedded --rig "$valid" -o "$tmp/valid_speech.glb" >/dev/null
    "$kinemo" animate "$speech" --embedded --rig "$godette" -o "$tmp/godette_speech.glb" >/dev/null
    outs+=("$tmp/valid_speech.glb" "$tmp/godette_speech.glb")
  else
    echo "note: kinemo_allinone not built: animate --rig not run"
  fi
  for out in "${outs[@]}"; do
    blender -b --factory-startup --python "$here/blender_import.py" -- "$out" >"$tmp/blender.log" 2>&1 || true
    grep '^KINEMO_BLENDER ' "$tmp/blender.log" | sed 's/^KINEMO_BLENDER //' >"$tmp/b.json"
    [[ -s "$tmp/b.json" ]] || fail "$(basename "$out"): Blender printed no report: $(tail -5 "$tmp/blender.log")"
    python3 - "$tmp/b.json" "$(basename "$out")" <<'PY' || fail "$(basename "$out"): $(cat "$tmp/b.json" | head -c 600)"
import json, sys
d = json.load(open(sys.argv[1]))
name = sys.argv[2]
print(f'{name}: armature fcurves {d.get("bone_fcurves")}, {d.get("bones_moving")} bones moving '
      f'(widest {d.get("bone_range_deg")} deg); shape keys on {d.get("meshes_with_shape_keys")}: '
      f'{d.get("shape_key_fcurves")} fcurves, {d.get("shape_keys_changing")} changing (range {d.get("shape_key_range")}), '
      f'{d.get("frames")} frames')
assert not d["error"], d["error"]
assert d["armatures"] == 1 and d["bones_moving"] >= 20, "the armature does not move"
want = {"valid": (96, 10), "godette": (15, 3)}[name.split("_")[0]]
assert d["shape_key_fcurves"] >= want[0], "shape-key fcurves missing"
assert d["shape_keys_changing"] >= want[1], "shape keys do not change"
if name.startswith("godette"):
    changing = " ".join(d["shape_keys_changing_names"])
    assert "FaceMesh/ah" in changing or "FaceMesh/oh" in changing, "Godette's vowel shapes are not named"
PY
  done
  echo "PASS: Blender imported ${#outs[@]} GLBs with armature and shape-key animation"
  exit 0
fi

# validator
command -v npm >/dev/null && command -v node >/dev/null || { echo "SKIP: npm/node not installed"; exit 77; }
# The validator pinned by tests/tools/gltf_validator's committed lock:
# installed there by deploy/install-deps.sh --all; else here, into a copy.
tools="$src/tests/tools/gltf_validator"
if [[ ! -f "$tools/node_modules/gltf-validator/package.json" ]]; then
  cp "$tools/package.json" "$tools/package-lock.json" "$tmp/"
  tools="$tmp"
  (cd "$tools" && npm ci --no-audit --no-fund --loglevel=error >npm.log 2>&1) ||
    { echo "SKIP: npm ci of gltf-validator failed:"; tail -5 "$tools/npm.log"; exit 77; }
fi
"$kinemo" retarget "$smplx" --to "$man" -o "$tmp/man.glb"
"$kinemo" retarget "$bandai" --to "$woman" -o "$tmp/woman.glb"
"$kinemo" retarget "$smplx" --to "$robot" -o "$tmp/robot.glb"
face_file
"$kinemo" retarget "$take2.bvh" --to "$valid" --visemes "$tmp/face.json" -o "$tmp/valid.glb"
"$kinemo" retarget "$take2.bvh" --to "$godette" --visemes "$tmp/face.json" -o "$tmp/godette.glb"
"$kinemo" retarget "$take2.bvh" --to "$vrm1" --visemes "$tmp/face.json" -o "$tmp/vrm1.glb"
"$kinemo" retarget "$take2.bvh" --to "$data/characters/formats/quaternius_man_draco.glb" -o "$tmp/draco.glb"
"$kinemo" retarget "$take2.bvh" --to "$data/characters/formats/quaternius_man_mixamo.fbx" -o "$tmp/fbx.glb"
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
node "$tmp/validate.js" "$tools" "$tmp/man.glb" "$tmp/woman.glb" "$tmp/robot.glb" "$robot" "$tmp/valid.glb" \
  "$tmp/godette.glb" "$tmp/vrm1.glb" "$tmp/draco.glb" "$tmp/fbx.glb" | tee "$tmp/report.txt"
errors() { grep "^$1: " "$tmp/report.txt" | sed -E 's/^[^:]*: ([0-9]+) errors.*/\1/'; }
for f in man woman valid godette vrm1 draco fbx; do
  [[ "$(errors $f.glb)" == 0 ]] || fail "the glTF validator found errors in $f.glb"
done
# robot_expressive.glb itself has 752 errors (non-normalised skin weights in
# its meshes); the animated GLB must add none.
[[ "$(errors robot.glb)" == "$(errors robot_expressive.glb)" ]] || fail "retargeting added validator errors to the robot"
echo "PASS: 0 validator errors (faces on VALID, Godette, VRM 1.0; a Draco input; an FBX rig; the robot: only its own)"

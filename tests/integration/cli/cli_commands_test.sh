#!/usr/bin/env bash
# The `kinemo` subcommands that no other test runs, each on small real input
# from tests/data (LibriVox speech, Bandai and CMU capture, the Vleo cube), with
# its output checked: the numbers finite and consistent, the files it writes
# readable by another kinemo command or by their format's own header.
#
#   cli_commands_test.sh BUILD_DIR SOURCE_DIR CASE
#
# CASE: crf (corpus, train, evaluate, fig4), controller (build,
# synthesize, bench), gestures (gmg phrases -> gmg sweep on the manifest,
# gestures --output), locomotion (evaluate, plan, drive), preview, cube_net,
# store (library load, library ls --all, graph ls, graph rm, the artifact
# commands' refusals against a kinemo_allinone), bench (bench e2e, bench load
# on an embedded stack; bench micro; kinemo without kinemo-bench beside it).
set -euo pipefail
build="$(realpath "$1")"
src="$(realpath "$2")"
case_name="$3"
K="$build/services/cli/kinemo"
D="$src/tests/data"
WAV="$D/speech/sense_and_sensibility_01_austen_64kb-0870.wav"
tmp="$(mktemp -d)"
pid=""
cleanup() {
  if [[ -n "$pid" ]]; then kill -TERM "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# The embedded stacks the commands start keep their store here, not in $HOME.
export KINEMO_STORE_DIR="$tmp/home-store"

# PNG signature and IHDR size of FILE: prints "W H".
png_size() {
  python3 - "$1" <<'PY'
import struct, sys
b = open(sys.argv[1], 'rb').read(24)
assert b[:8] == b'\x89PNG\r\n\x1a\n' and b[12:16] == b'IHDR', f"{sys.argv[1]}: not a PNG"
print(*struct.unpack('>II', b[16:24]))
PY
}
# Frames of a BVH file, read back by `kinemo bvh info --json`.
bvh_frames() { "$K" bvh info "$1" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["num_frames"])'; }

# A small paired corpus and a model trained on it (crf, controller).
small_model() {
  "$K" crf corpus --out "$tmp/corpus" --speech "$WAV" "$D/speech/sense_and_sensibility_01_austen_64kb-0880.wav" \
    "$D/speech/sense_and_sensibility_01_austen_64kb-0930.wav" \
    --gestures "$D/planner_controller/dataset-1_bow_normal_001.bvh" "$D/planner_controller/dataset-1_guide_normal_001.bvh" \
    --renditions 2 --seed 1 >"$tmp/corpus.out"
  "$K" crf train --corpus "$tmp/corpus" --states 4 --window 2 --clusters 4 --restarts 1 --seed 1 \
    --out "$tmp/model.kmodel" --json >"$tmp/train.json"
}

case "$case_name" in
crf)
  small_model
  "$K" crf evaluate --model "$tmp/model.kmodel" --corpus "$tmp/corpus" --json >"$tmp/eval.json"
  # Hold out the recordings of one speech file (0930).
  "$K" crf fig4 --corpus "$tmp/corpus" --holdout sense_and_sensibility_01_austen_64kb-0930 --max-window 4 \
    --states 4 --clusters 4 --csv "$tmp/fig4.csv" --png "$tmp/fig4.png" >"$tmp/fig4.out"
  png_size "$tmp/fig4.png" >/dev/null
  python3 - "$tmp/train.json" "$tmp/eval.json" "$tmp/fig4.csv" "$tmp/fig4.out" <<'PY'
import csv, json, math, sys
train, ev = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
assert train["sequences"] == 6, train            # 3 recordings x 2 renditions
assert ev["steps"] == train["steps"] > 0, (ev, train)
assert math.isfinite(ev["crf_ll_per_step"]) and math.isfinite(ev["hmm_ll_per_step"]), ev
# evaluate, on the corpus the model was trained on and read back from its file,
# scores the CRF as training reported
assert abs(ev["crf_ll_per_step"] - train["crf_ll_per_step"]) <= 1e-4 * max(1.0, abs(train["crf_ll_per_step"])), (ev, train)
rows = list(csv.DictReader(l for l in open(sys.argv[3]) if not l.startswith("#")))
assert [r["window"] for r in rows] == ["1", "2", "3", "4"], rows
steps = {r["steps"] for r in rows}
assert len(steps) == 1 and int(steps.pop()) > 0, rows   # the same held-out steps for each window
assert 0 < int(rows[0]["steps"]) < train["steps"], rows   # held out: a part of the corpus
for r in rows:
    assert math.isfinite(float(r["crf_ll_per_step"])) and math.isfinite(float(r["hmm_ll_per_step"])), r
out = open(sys.argv[4]).read()
assert all(f"window {w}: CRF" in out for w in range(1, 5)), out
print(f"crf: {train['steps']} steps, CRF {ev['crf_ll_per_step']:.3f} vs HMM {ev['hmm_ll_per_step']:.3f}; fig4 rows {len(rows)}")
PY
  ;;
controller)
  small_model
  "$K" controller build --library "$D/planner_controller" --model "$tmp/model.kmodel" --out "$tmp/ctrl.kctrl" \
    --threads 2 --json >"$tmp/build.json"
  "$K" controller synthesize --controller "$tmp/ctrl.kctrl" --speech "$WAV" --out "$tmp/synth.bvh" --json \
    >"$tmp/synth.json"
  "$K" audio info "$WAV" --json >"$tmp/audio.json"
  "$K" bvh info "$tmp/synth.bvh" --json >"$tmp/synth_info.json"
  "$K" controller bench --data-root "$D" --work-dir "$tmp/bench" --minutes 0.2 --states 3 --json >"$tmp/bench.json"
  python3 - "$tmp/build.json" "$tmp/synth.json" "$tmp/audio.json" "$tmp/synth_info.json" "$tmp/bench.json" <<'PY'
import json, math, sys
build, synth, audio, info, bench = (json.load(open(p)) for p in sys.argv[1:6])
print("controller build:", build)
print("controller synthesize:", synth)
print("controller bench:", bench)
assert info["num_frames"] > 0, info
# the motion lasts as long as the speech (within a frame or two of the end)
assert abs(info["duration_s"] - audio["duration_s"]) < 0.5, (info["duration_s"], audio["duration_s"])
for v in bench.values():
    if isinstance(v, (int, float)):
        assert math.isfinite(v) and v >= 0, bench
assert bench["entries"] > 0 and 0 <= bench["culled_fraction"] <= 1, bench
PY
  ;;
gestures)
  "$K" gmg phrases --library "$D/planner_gesture" >"$tmp/phrases.json"
  # The manifest it prints is a library in its own right: sweep over it.
  "$K" gmg sweep --library "$tmp/phrases.json" --thresholds 0.5,0.7 --json >"$tmp/sweep.json"
  # The deprecated --output still writes the BVH (and says it is deprecated).
  "$K" gestures "$WAV" --library "$D/planner_gesture" --output "$tmp/g.bvh" --no-recognize >"$tmp/g.out" 2>"$tmp/g.err"
  grep -q -- '--output is deprecated.*use --out' "$tmp/g.err" || fail "gestures --output: no deprecation note: $(cat "$tmp/g.err")"
  [[ "$(bvh_frames "$tmp/g.bvh")" -gt 0 ]] || fail "gestures --output wrote no frames"
  python3 - "$tmp/phrases.json" "$tmp/sweep.json" "$D/planner_gesture" <<'PY'
import glob, json, os, sys
m, sweep = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
clips = sorted(os.path.basename(p) for p in glob.glob(os.path.join(sys.argv[3], "*.bvh")))
assert sorted(os.path.basename(c["path"]) for c in m["clips"]) == clips, m
n = 0
for c in m["clips"]:
    for p in c["phrases"]:
        assert 0 <= p["start_s"] <= p["apex_s"] <= p["end_s"], p
        phases = p["phases"]
        assert "stroke" in {x["phase"] for x in phases}, p
        # the phases tile the phrase in order
        assert phases[0]["start_s"] == p["start_s"] and phases[-1]["end_s"] == p["end_s"], p
        assert all(x["end_s"] == y["start_s"] for x, y in zip(phases, phases[1:])), p
        n += 1
assert n >= len(clips), f"{n} phrases in {len(clips)} clips"
assert [r["st"] for r in sweep] == [0.5, 0.7], sweep
for r in sweep:
    assert r["size"] > 0 and 0 < r["scc_size"] <= r["size"], r
print(f"gmg phrases: {n} phrases in {len(clips)} clips; sweep {sweep}")
PY
  ;;
locomotion)
  # Bandai capture, one skeleton: walk and run (planner_locomotion) and a
  # standing clip as the idle (planner_gesture).
  L="$D/planner_locomotion"
  WALK=dataset-1_walk_normal_001
  RUN=dataset-1_run_active_001
  IDLE=dataset-1_respond_normal_001
  CLIPS=("$L/$WALK.bvh" "$L/$RUN.bvh")
  "$K" locomotion evaluate --clips "${CLIPS[@]}" --profiles SMG,SP5 --thresholds 0.4,0.8 --threads 2 --json \
    >"$tmp/eval.json"
  "$K" locomotion plan --clips "${CLIPS[@]}" --from "$WALK" --frame 10 --to "$RUN" --profile SMG --threshold 0.8 \
    --out "$tmp/plan.bvh" >"$tmp/plan.json"
  "$K" locomotion drive --clips "${CLIPS[@]}" "$D/planner_gesture/$IDLE.bvh" --idle "$IDLE" --walk "$WALK" --run "$RUN" \
    --target 2,0 --seconds 3 --profile SMG --threshold 0.8 --out "$tmp/drive.bvh" --json >"$tmp/drive.json"
  [[ "$(bvh_frames "$tmp/plan.bvh")" -gt 0 ]] || fail "locomotion plan wrote no frames"
  # 3 s at 30 fps
  [[ "$(bvh_frames "$tmp/drive.bvh")" -ge 89 ]] || fail "locomotion drive: $(bvh_frames "$tmp/drive.bvh") frames for 3 s"
  python3 - "$tmp/eval.json" "$tmp/plan.json" "$tmp/drive.json" <<'PY'
import json, sys
rows, plan, drive = (json.load(open(p)) for p in sys.argv[1:4])
print("locomotion evaluate:", rows)
print("locomotion plan:", plan)
print("locomotion drive:", drive)
assert sorted((r["method"], r["threshold"]) for r in rows) == [(m, t) for m in ("SMG", "SP5") for t in (0.4, 0.8)], rows
for r in rows:
    assert 0 < r["connectivity"] <= 1 and 1 <= r["connected_clips"] <= 2, r
smg = {r["threshold"]: r for r in rows if r["method"] == "SMG"}
# a looser threshold connects at least as much
assert smg[0.8]["connectivity"] >= smg[0.4]["connectivity"], smg
assert smg[0.8]["connected_clips"] == 2 and smg[0.8]["tbf_frames"] > 0, smg   # walk <-> run at 0.8 (the plan below)
assert plan["cost"] > 0 and plan["tbf_frames"] > 0 and plan["parts"], plan
# from the idle start towards (2, 0): closer than the 2 m it started from, walking
assert drive["transitions"] >= 1 and drive["final_distance_to_target_m"] < 2.0, drive
assert "walk" in {s["state"] for s in drive["states"]}, drive
PY
  ;;
preview)
  "$K" preview "$D/planner_gesture/dataset-1_guide_normal_001.bvh" -o "$tmp/sheet.png" --panels 6 --columns 3 \
    --panel-px 100 >"$tmp/preview.out"
  read -r w h < <(png_size "$tmp/sheet.png")
  [[ "$w" -eq 300 && "$h" -ge 200 ]] || fail "preview: ${w}x${h} px for 6 panels of 100 px in 3 columns"
  grep -q '6 frames' "$tmp/preview.out" || fail "preview: $(cat "$tmp/preview.out")"
  echo "preview: ${w}x${h} px"
  ;;
cube_net)
  "$K" cube net --model "$D/cube/vleo.cube" --out "$tmp/net.png" --dpi 50 >"$tmp/net.out"
  read -r w h < <(png_size "$tmp/net.png")
  grep -q "${w}x${h} px at 50 dpi" "$tmp/net.out" || fail "cube net: said $(cat "$tmp/net.out"), wrote ${w}x${h}"
  # The same net at twice the resolution: twice the pixels each way.
  "$K" cube net --model "$D/cube/vleo.cube" --out "$tmp/net100.png" --dpi 100 >/dev/null
  read -r w2 h2 < <(png_size "$tmp/net100.png")
  (( w2 >= 2 * w - 2 && w2 <= 2 * w + 2 && h2 >= 2 * h - 2 && h2 <= 2 * h + 2 )) ||
    fail "cube net: ${w}x${h} at 50 dpi but ${w2}x${h2} at 100 dpi"
  echo "cube net: ${w}x${h} px at 50 dpi"
  ;;
store)
  cat >"$tmp/allinone.textproto" <<EOF
server { host: "127.0.0.1" port: 0 log_level: "warn" shutdown_grace_s: 1 }
store_dir: "$tmp/store"
seed_store_dir: "$tmp/no-seed"
planner {
  library_root: "$D"
  preload { library_id: "gestures" paths: "planner_gesture" }
  preload_gesture_graphs { graph_id: "g" library_id: "gestures" }
}
EOF
  "$build/services/allinone/kinemo_allinone" --config "$tmp/allinone.textproto" --port-file "$tmp/port" \
    >"$tmp/allinone.log" 2>&1 &
  pid=$!
  for _ in $(seq 1 1200); do
    [[ -s "$tmp/port" ]] && break
    kill -0 "$pid" 2>/dev/null || fail "kinemo_allinone exited: $(tail -5 "$tmp/allinone.log")"
    sleep 0.05
  done
  [[ -s "$tmp/port" ]] || fail "kinemo_allinone did not write its port"
  S="127.0.0.1:$(cat "$tmp/port")"
  "$K" library load --path planner_controller --id ctl --server "$S" --json >"$tmp/load.json"
  "$K" library ls --all --server "$S" --json >"$tmp/libs.json"
  "$K" graph ls --server "$S" --json >"$tmp/graphs.json"
  "$K" graph ls --all-versions --server "$S" --json >"$tmp/graphs_old.json" 2>"$tmp/graphs_old.err"
  grep -q -- '--all-versions is deprecated.*use --all' "$tmp/graphs_old.err" || fail "graph ls --all-versions: no note"
  # The artifact commands' two families (services/cli/artifact_commands.h):
  # their table, their bad ID@VERSION, the id no kind holds, their lines.
  "$K" graph ls --server "$S" >"$tmp/graphs.txt"
  grep -q '^gesture_graphs:$' "$tmp/graphs.txt" && grep -q '^locomotion_graphs:$' "$tmp/graphs.txt" &&
    grep -q '^g  *v1 ' "$tmp/graphs.txt" || fail "graph ls: $(cat "$tmp/graphs.txt")"
  refused() {  # refused EXPECTED_STDERR ARGS...: exit 2, that message, nothing on stdout
    local want="$1" rc=0
    shift
    "$K" "$@" --server "$S" >"$tmp/refused.out" 2>"$tmp/refused.err" || rc=$?
    [[ $rc == 2 && "$(cat "$tmp/refused.err")" == "$want" && ! -s "$tmp/refused.out" ]] ||
      fail "$* -> $rc: $(cat "$tmp/refused.err") $(cat "$tmp/refused.out")"
  }
  refused "kinemo model rm: ID@VERSION: 'x@0': the version must be a number from 1" model rm x@0
  refused "kinemo controller: ID: 'x@v2': the version after @ must be a number >= 1" controller rm x@v2
  refused "kinemo library: ID: '@3' has no id" library rm @3
  refused "kinemo graph: ID: no 'g'" graph rm g --kind locomotion
  refused "kinemo cube rm: cube_tracker: ref.id: no cubes 'g'" cube rm g
  "$K" graph rm g --server "$S" >"$tmp/rm.out"
  [[ "$(cat "$tmp/rm.out")" == "deleted gesture_graphs/g/1" ]] || fail "graph rm: $(cat "$tmp/rm.out")"
  "$K" graph ls --server "$S" --json >"$tmp/graphs_after.json"
  python3 - "$tmp"/load.json "$tmp"/libs.json "$tmp"/graphs.json "$tmp"/graphs_old.json "$tmp"/graphs_after.json \
    "$D/planner_controller" <<'PY'
import glob, json, os, sys
load, libs, graphs, graphs_old, after = (json.load(open(p)) for p in sys.argv[1:6])
def get(d, *names):
    for n in names:
        if n in d: return d[n]
    raise KeyError(f"{names} not in {d}")
clips = glob.glob(os.path.join(sys.argv[6], "*.bvh"))
assert get(load, "library_id", "libraryId") == "ctl", load
assert len(get(load, "clips")) == len(clips), (len(load["clips"]), len(clips))
ids = lambda l: sorted(a["ref"]["id"] for a in l)
assert ids(libs) == ["ctl", "gestures"], libs
assert ids(graphs) == ["g"] and graphs == graphs_old, (graphs, graphs_old)
assert after == [], after
print("library load:", get(load, "library_id", "libraryId"), len(load["clips"]), "clips; graphs", ids(graphs), "-> rm ->", after)
PY
  ;;
bench)
  # An embedded kinemo_allinone seeded from the bundled store (the build's kinemo_seed_store).
  "$K" bench e2e --actions 4 --sessions 2 --json >"$tmp/e2e.json"
  "$K" bench load --streams 1,2 --max-streams 2 --json >"$tmp/load.json"
  python3 - "$tmp/e2e.json" "$tmp/load.json" <<'PY'
import json, math, sys
e2e = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
load = [json.loads(l) for l in open(sys.argv[2]) if l.strip()]
print("bench e2e:", e2e)
print("bench load:", load)
assert len(e2e) == 1, e2e
assert e2e[0]["sessions"] == 2 and e2e[0]["speech_s"] > 0, e2e            # --sessions 2, the bundled clip
assert [r["streams"] for r in load] == [1, 2], load
for r in load:
    assert r["admitted"] == r["streams"] and r["failed"] == 0 and r["refused"] == 0, r   # --max-streams 2
for r in e2e + load:
    for k, v in r.items():
        if isinstance(v, float):
            assert math.isfinite(v) and v >= 0, (k, r)
PY
  # `kinemo bench` runs kinemo-bench from beside kinemo. A kinemo without it
  # (README command 1 builds none) says so and how to build it, and fails.
  mkdir "$tmp/solo" && cp "$K" "$tmp/solo/kinemo"
  if "$tmp/solo/kinemo" bench e2e --json >"$tmp/solo.out" 2>"$tmp/solo.err"; then fail "bench without kinemo-bench succeeded"; fi
  grep -q "kinemo bench: kinemo-bench is not built here" "$tmp/solo.err" || fail "bench without kinemo-bench: $(cat "$tmp/solo.err")"
  grep -q -- "--target kinemo-bench" "$tmp/solo.err" || fail "bench without kinemo-bench names no target: $(cat "$tmp/solo.err")"
  [[ ! -s "$tmp/solo.out" ]] || fail "bench without kinemo-bench printed: $(cat "$tmp/solo.out")"
  # `kinemo --help` lists bench; kinemo-bench lists its four benchmarks.
  help=$("$K" --help)
  grep -q "^  bench " <<<"$help" || fail "kinemo --help does not list bench: $help"
  help=$("$K" bench --help)
  for b in e2e load chaos tones long micro; do
    grep -q "^  $b " <<<"$help" || fail "kinemo bench --help does not list $b: $help"
  done
  # `kinemo bench micro` runs the Google Benchmark suite inside kinemo-bench
  # (one bench binary), its flags passed as they are; a build without the
  # suite (KINEMO_BUILD_BENCHMARKS=OFF) says how to get it.
  if "$K" bench micro --benchmark_filter='^BM_ProtoLiveBatch' --benchmark_min_time=0.01 \
      --benchmark_format=json >"$tmp/micro.json" 2>"$tmp/micro.err"; then
    python3 - "$tmp/micro.json" <<'PY' || fail "bench micro: $(head -c 2000 "$tmp/micro.json")"
import json, sys
runs = json.load(open(sys.argv[1]))["benchmarks"]
names = sorted(r["name"] for r in runs)
assert names == ["BM_ProtoLiveBatchParse", "BM_ProtoLiveBatchSerialize"], names
assert all(r["iterations"] > 0 and r["cpu_time"] > 0 for r in runs), runs
PY
  else
    grep -q -- "-DKINEMO_BUILD_BENCHMARKS=ON" "$tmp/micro.err" || fail "bench micro failed: $(cat "$tmp/micro.err")"
  fi
  if "$K" bench micro --benchmark_no_such_flag >"$tmp/micro.out" 2>"$tmp/micro.err"; then fail "bench micro took an unknown flag"; fi
  grep -q -- "--benchmark_no_such_flag\|-DKINEMO_BUILD_BENCHMARKS=ON" "$tmp/micro.err" || fail "bench micro, unknown flag: $(cat "$tmp/micro.err")"
  ;;
*)
  fail "unknown case $case_name"
  ;;
esac
echo "PASS: $case_name"

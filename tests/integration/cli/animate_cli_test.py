#!/usr/bin/python3
"""`kinemo animate` as a new user runs it (issue 42), against an embedded
kinemo_allinone whose messages are limited to 1 MiB, so that every hop of a
two-minute recording is larger than a message:
  - long recordings: two minutes of the bundled speech as a 44.1 kHz stereo
    WAV (21 MB) and as an MP3, made by `kinemo bench long` (which runs
    `kinemo animate ... --json` itself and reports its memory), animate with
    every method; the JSON line has audio_s, frames, peak_rss_mb; progress
    goes to stderr; the BVH plays in `kinemo preview`;
  - errors a user can reach with a bad file or flag: exit 2, the message
    names the file or the option and says what is wrong, no "(code N)", no
    request field paths (they are in --json's "detail"), no temporary path;
  - --rig: the result is the character; the line printed names it, not a
    temporary BVH.

  animate_cli_test.py BUILD_DIR SOURCE_DIR
"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

build, src = sys.argv[1], sys.argv[2]
KINEMO = os.path.join(build, "services/cli/kinemo")
DATA = os.path.join(src, "tests/data")
CLIP = os.path.join(DATA, "speech/sense_and_sensibility_01_austen_64kb-0870.wav")
tmp = tempfile.mkdtemp(prefix="kinemo-cli-test-")
env = dict(os.environ, KINEMO_STORE_DIR=os.path.join(tmp, "home-store"))
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def run(args, timeout=600):
    p = subprocess.run([KINEMO] + args, capture_output=True, text=True, timeout=timeout, env=env)
    return p.returncode, p.stdout, p.stderr


def path(name):
    return os.path.join(tmp, name)


# The bundled stack's options with every message at most 1 MiB.
config = path("allinone.textproto")
with open(config, "w") as f:
    f.write(f'''server {{ max_message_bytes: 1048576 }}
store_dir: "{path("store")}"
coordinator {{ animate {{ default_method: METHOD_BODYSPEECH models {{ gesture_graph_id: "bundled" inference_model_id: "bundled" controller_id: "bundled" }} }} }}
planner {{
  library_root: "{DATA}"
  preload {{ library_id: "bundled" paths: "paired/beat2" }}
  preload_gesture_graphs {{ graph_id: "bundled" library_id: "bundled" params {{ stroke_phrases: true }} }}
}}
''')
stack = ["--embedded", "--allinone-config", config]

try:
    # ---- Long recordings, every method, WAV and MP3.
    for fmt, method in (("wav", "bodyspeech"), ("mp3", "gmg")):
        keep = path(f"long-{fmt}")
        p = subprocess.run([KINEMO, "bench", "long", "--minutes", "2", "--format", fmt, "--method", method,
                            "--keep", keep, "--allinone-config", config, "--preview", "--json"],
                           capture_output=True, text=True, timeout=900, env=env)
        if p.returncode != 0:
            fail(f"bench long {fmt} {method}: exit {p.returncode}: {p.stderr[-2000:]}")
            continue
        j = json.loads(p.stdout.strip().splitlines()[-1])
        for k in ("minutes", "seconds", "peak_rss_mb", "rss_mb_per_min"):
            if k not in j:
                fail(f"bench long --json: no {k}: {j}")
        if abs(j["audio_s"] - 120) > 0.5 or abs(j["frames"] - 3600) > 30 or not j.get("preview_ok"):
            fail(f"bench long {fmt} {method}: {j}")
        if j["file_mb"] * (1 << 20) < (1 << 20) or j["bvh_mb"] < 1:
            fail(f"bench long {fmt}: the recording and the motion should each be larger than a message: {j}")
        if not (0 < j["peak_rss_mb"] < 1500):
            fail(f"bench long {fmt}: peak_rss_mb {j['peak_rss_mb']}")
        print(f"bench long 2 min {fmt} {method}: {j['seconds']:.1f} s, peak {j['peak_rss_mb']:.0f} MB")
    wav = path("long-wav/long-2.0min-44100hz-2ch.wav")
    if os.path.exists(wav):
        rc, out, err = run(["animate", wav, "--method", "gc", "-o", path("gc.bvh"), "--json"] + stack)
        if rc != 0:
            fail(f"animate --method gc of two minutes: exit {rc}: {err[-2000:]}")
        else:
            j = json.loads(out.strip().splitlines()[-1])
            if abs(j["audio_s"] - 120) > 0.5 or abs(j["frames"] - 3600) > 30 or j["peak_rss_mb"] <= 0:
                fail(f"animate --json: {j}")
            if j.get("method") != "METHOD_GESTURE_CONTROLLER":
                fail(f"animate --method gc ran {j.get('method')}")
            for progress in ("sent 2:00 of 2:00", "analysing the speech", "inferring the gesture style",
                             "making the motion"):
                if progress not in err:
                    fail(f"animate of two minutes: no progress line '{progress}' on stderr: {err[-1500:]}")
            rc, out, err = run(["preview", path("gc.bvh"), "-o", path("gc.png")])
            if rc != 0 or os.path.getsize(path("gc.png")) == 0:
                fail(f"kinemo preview of the long BVH: exit {rc}: {err}")
            # The text line: length, method, frames, the output.
            rc, out, err = run(["animate", wav, "-o", path("text.bvh")] + stack)
            if rc != 0 or not re.search(r"2:00 of speech, \d+ syllables, \d+ accents -> .*text\.bvh "
                                        r"\(METHOD_BODYSPEECH, \d+ frames\)", out):
                fail(f"animate's summary line: exit {rc}: {out} {err[-500:]}")

    # ---- Errors a user can reach.
    open(path("empty.wav"), "w").close()
    with open(path("notes.wav"), "w") as f:
        f.write("Dear diary, this is text renamed to .wav, not a recording.\n")
    with open(CLIP, "rb") as f:
        head = f.read(30000)
    with open(path("cut.wav"), "wb") as f:
        f.write(head)

    def expect_error(name, args, must, code=2, needs_stack=False):
        rc, out, err = run(["animate"] + args + (stack if needs_stack else []) + ["--json"])
        words = err.strip()
        if rc != code:
            fail(f"{name}: exit {rc}, want {code}: {words}")
        for m in must:
            if m not in words:
                fail(f"{name}: '{m}' not in: {words}")
        for leak in ("(code", "config.request", "audio.data", "/tmp/kinemo-animate-", "prosody:", "planner:"):
            if leak in words:
                fail(f"{name}: '{leak}' in the message: {words}")
        if "not expected" not in words:  # CLI11's own usage errors print no JSON
            try:
                j = json.loads(out.strip().splitlines()[-1])
                if not (j.get("error") and j.get("code") and j.get("detail")):
                    fail(f"{name}: --json error line without error/code/detail: {out}")
            except (ValueError, IndexError):
                fail(f"{name}: no JSON error line with --json: {out!r}")
        print(f"{name}: exit {rc}: {words.splitlines()[-1] if words else ''}")

    expect_error("empty file", [path("empty.wav"), "-o", path("x.bvh")],
                 [path("empty.wav"), "empty file (0 bytes)"])
    expect_error("text renamed .wav", [path("notes.wav"), "-o", path("x.bvh")],
                 [path("notes.wav"), "not an audio file", "it starts with 'Dear'", "MP3"])
    expect_error("truncated WAV", [path("cut.wav"), "-o", path("x.bvh")],
                 [path("cut.wav"), "truncated WAV", "cut short"])
    expect_error("missing file", [path("none.wav"), "-o", path("x.bvh")], [path("none.wav"), "no such file"])
    expect_error("unknown method", [CLIP, "-o", path("x.bvh"), "--method", "dance"],
                 ["--method", "'dance'", "gc, gmg or bodyspeech"])
    expect_error("missing rig file", [CLIP, "-o", path("x.glb"), "--rig", path("none.glb")],
                 ["--rig", path("none.glb"), "no such file"])
    expect_error("unknown option", [CLIP, "-o", path("x.bvh"), "--dance"], ["--dance"])
    expect_error("a .glb without --rig", [CLIP, "-o", path("x.glb")], ["-o", "x.glb", "--rig"])
    expect_error("no output", [CLIP], ["-o/--out is required"])
    expect_error("unknown graph", [CLIP, "-o", path("x.bvh"), "--graph-id", "nope", "--method", "gmg"],
                 ["--graph-id: no gesture graph 'nope'", "kinemo graph ls"], needs_stack=True)
    if os.path.exists(path("x.bvh")) or os.path.exists(path("x.glb")):
        fail("a failed animate left an output file")
    leftovers = [f for f in os.listdir(tmp) if ".part" in f]
    if leftovers:
        fail(f"partial outputs left behind: {leftovers}")

    # ---- --rig: the character is the result, named in the line printed.
    rc, out, err = run(["animate", CLIP, "--rig", os.path.join(DATA, "characters/quaternius_man_casual.glb"),
                        "-o", path("man.glb")] + stack)
    if rc != 0:
        fail(f"animate --rig: exit {rc}: {err}")
    else:
        if "/tmp/kinemo-animate-" in out + err or "man.glb" not in out:
            fail(f"animate --rig names a temporary file or not the output: {out} {err}")
        with open(path("man.glb"), "rb") as f:
            if f.read(4) != b"glTF":
                fail("animate --rig wrote no GLB")
finally:
    shutil.rmtree(tmp, ignore_errors=True)

if failures:
    print(f"{len(failures)} failure(s)", file=sys.stderr)
    sys.exit(1)
print("PASS")

#!/usr/bin/python3
"""`kinemo animate` on a long recording (issue 42), fast: the five LibriVox
clips of tests/data/speech (16 kHz mono, 36 s together), one after the other
with half-second pauses until 2 min 10 s, written as a 44.1 kHz stereo
16-bit WAV (22.9 MB), animated through an embedded kinemo_allinone (its
services on ephemeral ports) whose messages are limited to 1 MiB, so the
recording and the motion are each larger than a message on every hop:
  - exit 0; the BVH has 30 frames a second of the recording (Frame Time
    1/30, its frame count the recording's length, every motion line with a
    value per channel of the hierarchy);
  - --json: audio_s, frames (the BVH's), motion_bytes (the file's size),
    peak_rss_mb, call (AnimateChunked), the method;
  - progress on stderr (sent, analysing, making the motion);
  - the text summary line: length, syllables, accents, output, method,
    frames;
  - the face (issue 38) on the long recording too: --json face_frames equals
    frames, --visemes V.json has a face frame per motion frame, the BVH's
    SMPL-X `jaw` is the face's jaw opening (rest + opening x hinge, frame for
    frame), moving with the voice (open in speech, at rest in the pauses);
  - the first 20 s of the same file (under 90 s) through Animate in one
    message on the default embedded stack, with the same frames a second and
    a face per frame (the bundled face model), and that face is the long
    recording's over those 20 s: the jaw within 0.15 degrees on average,
    the dominant OVR viseme the same on most frames.

  animate_long_test.py BUILD_DIR SOURCE_DIR
"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
import wave

with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)  # audioop: in the standard library up to Python 3.12
    import audioop

build, src = sys.argv[1], sys.argv[2]
KINEMO = os.path.join(build, "services/cli/kinemo")
DATA = os.path.join(src, "tests/data")
CLIPS = [os.path.join(DATA, f"speech/sense_and_sensibility_01_austen_64kb-{n}.wav")
         for n in ("0870", "0880", "0890", "0920", "0930")]
SECONDS = 130.0
RATE = 44100
tmp = tempfile.mkdtemp(prefix="kinemo-animate-long-")
env = dict(os.environ, KINEMO_STORE_DIR=os.path.join(tmp, "home-store"))
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def path(name):
    return os.path.join(tmp, name)


def run(args, timeout=240):
    p = subprocess.run([KINEMO] + args, capture_output=True, text=True, timeout=timeout, env=env)
    return p.returncode, p.stdout, p.stderr


def long_recording(out, seconds):
    """The clips, each followed by 0.5 s of silence, repeated to `seconds`,
    at 44.1 kHz stereo 16-bit."""
    pcm16k = b""
    speech = []
    for clip in CLIPS:
        with wave.open(clip) as w:
            assert (w.getframerate(), w.getnchannels(), w.getsampwidth()) == (16000, 1, 2), clip
            speech.append(w.readframes(w.getnframes()) + b"\0\0" * 8000)
    while len(pcm16k) < seconds * 16000 * 2:
        for s in speech:
            pcm16k += s
    pcm16k = pcm16k[:int(seconds * 16000) * 2]
    up, _ = audioop.ratecv(pcm16k, 2, 1, 16000, RATE, None)
    stereo = audioop.tostereo(up, 2, 1, 1)
    with wave.open(out, "wb") as w:
        w.setnchannels(2)
        w.setsampwidth(2)
        w.setframerate(RATE)
        w.writeframes(stereo)
    with wave.open(out) as w:
        return w.getnframes() / w.getframerate()


# common/face/jaw.h: the SMPL-X jaw's hinge and rest, Euler Z X Y degrees.
JAW_HINGE = (0.0954, 0.9954, 0.0044)
JAW_REST = (-0.1292, -0.1884, -0.0923)


def bvh_jaw_opening(bvh):
    """The `jaw` joint's opening (degrees about the hinge) on every frame."""
    with open(bvh) as f:
        text = f.read()
    head, _, motion = text.partition("\nMOTION\n")
    column, cols = 0, None
    for m in re.finditer(r"(?:ROOT|JOINT)\s+(\S+)[^C]*?CHANNELS\s+(\d+)((?:\s+[XYZ](?:position|rotation))*)", head):
        names = m.group(3).split()
        if m.group(1) == "jaw":
            cols = [column + names.index(n) for n in ("Zrotation", "Xrotation", "Yrotation")]
        column += int(m.group(2))
    if cols is None:
        return None
    lines = motion.split("\n")[2:]
    out = []
    for line in lines:
        v = line.split()
        if v:
            out.append(sum((float(v[c]) - JAW_REST[i]) * JAW_HINGE[i] for i, c in enumerate(cols)))
    return out


def pearson(a, b):
    n = min(len(a), len(b))
    a, b = a[:n], b[:n]
    ma, mb = sum(a) / n, sum(b) / n
    sab = sum((x - ma) * (y - mb) for x, y in zip(a, b))
    sa = sum((x - ma) ** 2 for x in a) ** 0.5
    sb = sum((y - mb) ** 2 for y in b) ** 0.5
    return sab / (sa * sb) if sa > 0 and sb > 0 else 0.0


def dominant(weights):
    return max(range(len(weights)), key=lambda i: weights[i])


def check_bvh(bvh, audio_s, what):
    """The BVH's frame count and time against the recording: returns its frames."""
    with open(bvh) as f:
        text = f.read()
    channels = sum(int(n) for n in re.findall(r"CHANNELS (\d+)", text))
    m = re.search(r"\nFrames:\s*(\d+)\s*\nFrame Time:\s*([0-9.]+)\s*\n", text)
    if not m:
        fail(f"{what}: no Frames/Frame Time in the BVH")
        return -1
    frames, frame_time = int(m.group(1)), float(m.group(2))
    lines = text[m.end():].strip().split("\n")
    if abs(frame_time - 1 / 30) > 1e-6:
        fail(f"{what}: Frame Time {frame_time}, want 1/30")
    if abs(frames * frame_time - audio_s) > 2 * frame_time:
        fail(f"{what}: {frames} frames x {frame_time} s = {frames * frame_time:.3f} s, the recording is {audio_s:.3f} s")
    if len(lines) != frames:
        fail(f"{what}: {len(lines)} motion lines, Frames: {frames}")
    bad = [i for i, line in enumerate(lines) if len(line.split()) != channels]
    if bad:
        fail(f"{what}: {len(bad)} motion lines without {channels} values (first: line {bad[0]})")
    return frames


try:
    wav = path("long.wav")
    audio_s = long_recording(wav, SECONDS)
    if abs(audio_s - SECONDS) > 0.001 or os.path.getsize(wav) < 20 << 20:
        fail(f"the recording: {audio_s} s, {os.path.getsize(wav)} bytes")
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

    # --json: the fields, the BVH against them and the recording.
    rc, out, err = run(["animate", wav, "-o", path("long.bvh"), "--json", "--visemes", path("long.json")] + stack)
    if rc != 0:
        fail(f"animate {SECONDS:.0f} s --json: exit {rc}: {err[-2000:]}")
    else:
        j = json.loads(out.strip().splitlines()[-1])
        frames = check_bvh(path("long.bvh"), audio_s, "long.bvh")
        if abs(j.get("audio_s", 0) - audio_s) > 0.01:
            fail(f"--json audio_s {j.get('audio_s')}, the recording is {audio_s}")
        if j.get("frames") != frames:
            fail(f"--json frames {j.get('frames')}, the BVH has {frames}")
        if j.get("motion_bytes") != os.path.getsize(path("long.bvh")):
            fail(f"--json motion_bytes {j.get('motion_bytes')}, the BVH is {os.path.getsize(path('long.bvh'))} bytes")
        if not (0 < j.get("peak_rss_mb", 0) < 1500):
            fail(f"--json peak_rss_mb {j.get('peak_rss_mb')}")
        if j.get("call") != "AnimateChunked" or j.get("method") != "METHOD_BODYSPEECH":
            fail(f"--json call/method: {j.get('call')} {j.get('method')}")
        if j.get("prosody", {}).get("syllables", 0) < 200:
            fail(f"--json prosody: {j.get('prosody')}")
        for progress in ("long.wav: sent 2:10 of 2:10", "long.wav: analysing the speech",
                         "long.wav: making the motion"):
            if progress not in err:
                fail(f"no progress line '{progress}' on stderr: {err[-1500:]}")
        print(f"{audio_s:.1f} s 44.1 kHz stereo: {frames} frames, {j['motion_bytes'] >> 20} MB of BVH, "
              f"peak {j['peak_rss_mb']:.0f} MB, {j['times']['total_s']:.1f} s in the stack")
        # The face: one frame per motion frame, and the BVH's jaw is its jaw.
        if j.get("face_frames") != frames:
            fail(f"--json face_frames {j.get('face_frames')}, frames {frames}")
        with open(path("long.json")) as f:
            long_face = json.load(f)
        faces = long_face.get("frames", [])
        if len(faces) != frames or abs(long_face.get("frame_time_s", 0) - 1 / 30) > 1e-6:
            fail(f"--visemes: {len(faces)} face frames at {long_face.get('frame_time_s')} s, the BVH has {frames}")
        jaw_face = [f.get("jaw_deg", 0) for f in faces]
        jaw_bvh = bvh_jaw_opening(path("long.bvh")) or []
        if len(jaw_bvh) != frames:
            fail(f"the BVH's jaw: {len(jaw_bvh)} frames of {frames}")
        else:
            off = max(abs(a - b) for a, b in zip(jaw_bvh, jaw_face))
            spread = (sum(x * x for x in jaw_bvh) / frames - (sum(jaw_bvh) / frames) ** 2) ** 0.5
            r = pearson(jaw_bvh, jaw_face)
            if off > 1e-3 or r < 0.999:
                fail(f"the BVH's jaw is not the face's: off by up to {off:.4f} degrees, r = {r:.4f}")
            if spread < 0.2:
                fail(f"the BVH's jaw barely moves: sd {spread:.3f} degrees")
            # With the voice: the frames of digital silence (the pauses put
            # between the clips) against the frames of speech.
            with wave.open(wav) as w:
                pcm = w.readframes(w.getnframes())
            step = RATE // 30 * 4  # 1/30 s of 16-bit stereo
            silent = [audioop.rms(pcm[i * step:(i + 1) * step], 2) < 30 for i in range(frames)]
            quiet = [x for x, q in zip(jaw_bvh, silent) if q]
            spoken = [x for x, q in zip(jaw_bvh, silent) if not q]
            q_mean, s_mean = sum(quiet) / max(1, len(quiet)), sum(spoken) / max(1, len(spoken))
            print(f"jaw: sd {spread:.2f} degrees, mean {s_mean:.2f} in speech ({len(spoken)} frames), "
                  f"{q_mean:.2f} in the pauses ({len(quiet)} frames); BVH vs face r = {r:.4f}")
            if len(quiet) < 100 or not s_mean > q_mean + 0.5:
                fail(f"the jaw does not follow the voice: mean {s_mean:.2f} degrees in speech, {q_mean:.2f} in pauses")

    # The text line: length, syllables, accents, output, method, frames.
    rc, out, err = run(["animate", wav, "-o", path("text.bvh")] + stack)
    m = re.search(r"long\.wav: 2:10 of speech, (\d+) syllables, (\d+) accents -> \S*text\.bvh "
                  r"\(METHOD_BODYSPEECH, (\d+) frames\) in [0-9.]+ s", out)
    if rc != 0 or not m:
        fail(f"animate's summary line: exit {rc}: {out!r} {err[-500:]}")
    else:
        frames = check_bvh(path("text.bvh"), audio_s, "text.bvh")
        if int(m.group(3)) != frames or int(m.group(1)) < 200 or int(m.group(2)) < 20:
            fail(f"summary line {m.group(0)!r}: the BVH has {frames} frames")

    # Under 90 s: one Animate call, on a stack with the default message size.
    with wave.open(wav) as w, wave.open(path("short.wav"), "wb") as o:
        o.setparams(w.getparams())
        o.writeframes(w.readframes(20 * RATE))
    rc, out, err = run(["animate", path("short.wav"), "-o", path("short.bvh"), "--json", "--embedded",
                        "--library", "bundled", "--method", "bodyspeech", "--visemes", path("short.json")])
    if rc != 0:
        fail(f"animate 20 s: exit {rc}: {err[-2000:]}")
    else:
        j = json.loads(out.strip().splitlines()[-1])
        frames = check_bvh(path("short.bvh"), 20.0, "short.bvh")
        if j.get("call") != "Animate" or j.get("frames") != frames or abs(j.get("audio_s", 0) - 20) > 0.01:
            fail(f"animate 20 s --json: {j}")
        # The default embedded stack has the bundled face model: a face per frame.
        if j.get("face_frames") != frames:
            fail(f"animate 20 s: {j.get('face_frames')} face frames, {frames} motion frames")
        # Animate's face of these 20 s against AnimateChunked's of the whole
        # file over the same 20 s (up to the last half second, where the 20 s
        # file's offline face model sees no more speech): the model normalises
        # each recording by its own mean, so close, not equal.
        with open(path("short.json")) as f:
            short = json.load(f)["frames"]
        with open(path("long.json")) as f:
            long_ = json.load(f)["frames"]
        n = min(len(short), len(long_), int(19.5 * 30))
        if n < 500:
            fail(f"face over 20 s: {len(short)} short and {len(long_)} long frames")
        else:
            a = [f["jaw_deg"] for f in short[:n]]
            b = [f["jaw_deg"] for f in long_[:n]]
            mean_abs = sum(abs(x - y) for x, y in zip(a, b)) / n
            r = pearson(a, b)
            same = sum(dominant(x["ovr"]) == dominant(y["ovr"]) for x, y in zip(short[:n], long_[:n])) / n
            print(f"first 20 s, Animate vs AnimateChunked: jaw mean |diff| {mean_abs:.3f} degrees, r = {r:.3f}; "
                  f"dominant OVR viseme the same on {100 * same:.1f} % of {n} frames")
            if mean_abs > 0.15 or r < 0.95 or same < 0.9:
                fail(f"the long recording's face over its first 20 s is not Animate's: jaw mean |diff| "
                     f"{mean_abs:.3f}, r {r:.3f}, dominant viseme {100 * same:.1f} %")
finally:
    shutil.rmtree(tmp, ignore_errors=True)

if failures:
    print(f"{len(failures)} failure(s)", file=sys.stderr)
    sys.exit(1)
print("PASS")

#!/usr/bin/env python3
"""Leave-one-take-out benchmark of the gesture generators on real paired data.

For each fold (train on one BEAT2 take, animate the other take's speech) every
row's motion is judged by `kinemo motion compare` against the real motion
recorded with that speech (docs/evaluation.md). Rows:
  GC            Gesture Controller: CRF trained on the train take, controller
                built on its motion, offline DP synthesis for the test speech
  GC online     the same controller's online policy
  GMG           Gesture Motion Graph on the train take's motion
  BodySpeech    BodySpeech on the train take's motion
  random        random segments of the GC library in random order (same
                segments, blending and planted feet: controller --policy random)
  other take    the train take's real motion (natural, but for other speech)
  GC Bandai     GC with the same CRF on the Bandai emblem library (22 joints)
  GMG Bandai    GMG on the Bandai emblem library
  still         the train take's first pose held for the whole speech
Columns: the compare measures (Hellinger distances, kinetic FD, jerk, hand
speed, moving/raised hands, beat consistency, accents in the synchrony window,
longest copy from the library, foot slide). The reference row is the test
take's own measures.

  bench/tools/gesture_loto.py [--build build] [--work /tmp/kinemo_loto]
                              [--json OUT.json] [--states 8] [--window 3]
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.dirname(os.path.dirname(here))

ap = argparse.ArgumentParser()
ap.add_argument("--build", default=os.path.join(root, "build"))
ap.add_argument("--data", default=os.path.join(root, "tests", "data", "paired", "beat2"))
ap.add_argument("--work", default="/tmp/kinemo_loto")
ap.add_argument("--json", default="", help="write every fold's rows here")
ap.add_argument("--states", default="8")
ap.add_argument("--window", default="3")
ap.add_argument("--seed", default="1")
args = ap.parse_args()

kinemo = os.path.join(args.build, "services", "cli", "kinemo")
takes = sorted(f[:-4] for f in os.listdir(args.data) if f.endswith(".bvh"))
if len(takes) != 2:
    sys.exit(f"need two takes in {args.data}, found {takes}")
bandai = [os.path.join(root, "tests", "data", d) for d in ("planner_gesture", "planner_controller")]


def run(cmd, log):
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=f, text=True)
        f.write(p.stdout)
    if p.returncode != 0:
        sys.exit(f"failed ({p.returncode}): {' '.join(cmd)}\nsee {log}")
    return p.stdout


def still_pose(src, out, frames):
    """src's first frame repeated `frames` times (same header)."""
    with open(src) as f:
        lines = f.read().splitlines()
    m = next(i for i, l in enumerate(lines) if l.strip() == "MOTION")
    first = lines[m + 3]
    with open(out, "w") as f:
        f.write("\n".join(lines[: m + 1]) + "\n")
        f.write(f"Frames: {frames}\n{lines[m + 2]}\n")
        f.write("\n".join([first] * frames) + "\n")


def wav_seconds(path):
    import wave
    try:
        with wave.open(path) as w:
            return w.getnframes() / w.getframerate()
    except wave.Error:  # 32-bit float WAV: read the header by hand
        import struct
        with open(path, "rb") as f:
            data = f.read()
        fmt = data.find(b"fmt ")
        rate, = struct.unpack("<I", data[fmt + 12:fmt + 16])
        bits, = struct.unpack("<H", data[fmt + 22:fmt + 24])
        ch, = struct.unpack("<H", data[fmt + 10:fmt + 12])
        d = data.find(b"data")
        size, = struct.unpack("<I", data[d + 4:d + 8])
        return size / (rate * ch * bits // 8)


COLUMNS = [
    ("hellinger_speed", "H spd", "{:.3f}"),
    ("hellinger_accel", "H acc", "{:.3f}"),
    ("fd_kinetic", "FD kin", "{:.2f}"),
    ("jerk_mean_m_s3", "jerk", "{:.1f}"),
    ("hand_speed_mean_m_s", "v mean", "{:.3f}"),
    ("hand_speed_p95_m_s", "v p95", "{:.3f}"),
    ("hands_moving_fraction", "moving", "{:.2f}"),
    ("hands_raised_fraction", "raised", "{:.2f}"),
    ("beat_consistency", "BC", "{:.3f}"),
    ("beat_consistency_chance", "BC rnd", "{:.3f}"),
    ("accent_sync_fraction", "sync", "{:.2f}"),
    ("accent_sync_chance", "sync rnd", "{:.2f}"),
    ("longest_copy_s", "copy s", "{:.1f}"),
    ("longest_copy_fraction", "copy %", "{:.0%}"),
    ("foot_slide_p95_m_s", "slide95", "{:.4f}"),
    ("max_joint_speed_m_s", "vmax", "{:.2f}"),
]


def fmt(v, f):
    if v is None:
        return "-"
    return f.format(v)


os.makedirs(args.work, exist_ok=True)
log = os.path.join(args.work, "log.txt")
open(log, "w").close()
folds = []
for train, test in ((takes[0], takes[1]), (takes[1], takes[0])):
    d = os.path.join(args.work, f"train_{train}")
    corpus = os.path.join(d, "corpus")
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(corpus)
    for ext in (".wav", ".bvh", ".TextGrid"):
        src = os.path.join(args.data, train + ext)
        if os.path.exists(src):
            os.symlink(src, os.path.join(corpus, train + ext))
    train_bvh = os.path.join(args.data, train + ".bvh")
    test_bvh = os.path.join(args.data, test + ".bvh")
    test_wav = os.path.join(args.data, test + ".wav")
    model = os.path.join(d, "crf.kmodel")
    run([kinemo, "crf", "train", "--corpus", corpus, "--states", args.states, "--window", args.window,
         "--out", model, "--seed", args.seed], log)
    outs = {}
    ctrl = os.path.join(d, "gc.kctrl")
    run([kinemo, "controller", "build", "--library", train_bvh, "--model", model, "--out", ctrl], log)
    for name, extra in (("GC", []), ("GC online", ["--policy", "online"]),
                        ("random", ["--policy", "random", "--seed", args.seed])):
        out = os.path.join(d, name.replace(" ", "_") + ".bvh")
        run([kinemo, "controller", "synthesize", "--controller", ctrl, "--speech", test_wav, "--out", out] + extra, log)
        outs[name] = (out, [train_bvh])
    for alg, name in (("gmg", "GMG"), ("bodyspeech", "BodySpeech")):
        out = os.path.join(d, name + ".bvh")
        run([kinemo, "gestures", test_wav, "--library", train_bvh, "--algorithm", alg, "--no-recognize", "-o", out], log)
        outs[name] = (out, [train_bvh])
    outs["other take"] = (train_bvh, [train_bvh])
    bctrl = os.path.join(d, "gc_bandai.kctrl")
    run([kinemo, "controller", "build", "--library", bandai[1], "--model", model, "--out", bctrl], log)
    out = os.path.join(d, "GC_Bandai.bvh")
    run([kinemo, "controller", "synthesize", "--controller", bctrl, "--speech", test_wav, "--out", out], log)
    outs["GC Bandai"] = (out, [bandai[1]])
    out = os.path.join(d, "GMG_Bandai.bvh")
    run([kinemo, "gestures", test_wav, "--library", bandai[0], "--algorithm", "gmg", "--no-recognize", "-o", out], log)
    outs["GMG Bandai"] = (out, [bandai[0]])
    still = os.path.join(d, "still.bvh")
    still_pose(train_bvh, still, int(round(wav_seconds(test_wav) * 30)))
    outs["still"] = (still, [train_bvh])

    rows = {}
    reference = None
    for name, (bvh, library) in outs.items():
        cmd = [kinemo, "motion", "compare", bvh, "--reference", test_bvh, "--audio", test_wav, "--json"]
        for lib in library:
            cmd += ["--library", lib]
        r = json.loads(run(cmd, log))
        rows[name] = r
        reference = r["reference"]
    reference = dict(reference)
    reference["hellinger_speed"] = reference["hellinger_accel"] = reference["fd_kinetic"] = 0.0
    reference["longest_copy_s"] = reference["longest_copy_fraction"] = None
    rows = {"reference (real)": reference, **rows}
    folds.append({"train": train, "test": test, "rows": rows})

    print(f"\nfold: train {train}, animate {test}'s speech, judged against {test}'s real motion")
    print(f"{'row':<17}" + "".join(f"{c[1]:>9}" for c in COLUMNS))
    for name, r in rows.items():
        print(f"{name:<17}" + "".join(f"{fmt(r.get(k), f):>9}" for k, _, f in COLUMNS))

# The natural band: each take's real motion judged against the other's.
band = [f["rows"]["other take"] for f in folds]
print("\nnatural band (one take's real motion vs the other's): "
      f"Hellinger speed {min(b['hellinger_speed'] for b in band):.3f}-{max(b['hellinger_speed'] for b in band):.3f}, "
      f"accel {min(b['hellinger_accel'] for b in band):.3f}-{max(b['hellinger_accel'] for b in band):.3f}, "
      f"kinetic FD {min(b['fd_kinetic'] for b in band):.2f}-{max(b['fd_kinetic'] for b in band):.2f}")
if args.json:
    with open(args.json, "w") as f:
        json.dump({"folds": folds, "columns": [c[0] for c in COLUMNS]}, f, indent=1)
    print(f"wrote {args.json}")

#!/usr/bin/env python3
"""Leave-one-take-out benchmark of the gesture generators on real paired data.

For each fold (train on one BEAT2 take, animate the other take's speech) every
row's motion is judged by `kinemo motion compare` against the real motion
recorded with that speech (docs/evaluation.md). Rows:
  reference (real) the test take's real motion (distances 0 by definition;
                its near copies of the train take: the natural level)
  GC            Gesture Controller: CRF trained on the train take, controller
                built on its motion, offline DP synthesis for the test speech
  GC online     the same controller's online policy
  GMG           Gesture Motion Graph on the train take's motion
  BodySpeech    BodySpeech on the train take's motion
  random        random segments of the GC library in random order (same
                segments, blending and planted feet: controller --policy random)
  other take    the train take's real motion (natural, but for other speech:
                the speaker's natural band)
  MambaTalk (peer)  a published peer's own output for take 2_2's speech
                (../shared/data/paired/beat2/peers, fold that judges 2_2;
                "absent" when the shared data is missing)
  GC Bandai     GC with the same CRF on the Bandai emblem library (22 joints)
  GMG Bandai    GMG on the Bandai emblem library
  still         the train take's first pose held for the whole speech

Then, per fold, a matched / mismatched table in the manner of GENEA 2023's
appropriateness study: each method's motion for the test take's own speech
(matched) and the same method's motion for the other take's speech
(mismatched), both scored against the test take's real motion and speech:
  r motion   Pearson r of the 0.5 s hand-speed envelopes with the real motion
  r speech   Pearson r of the 0.5 s hand-speed envelope with the speech's
             loudness envelope
  BC         BEAT/EMAGE beat consistency with the speech's onsets
The real speaker's row is the ceiling: the take's real motion (matched) and
the other take's real motion (mismatched).

Last, each measure's natural band: the other take's value in each fold.

  bench/tools/gesture_loto.py [--build build] [--work /tmp/kinemo_loto]
                              [--json OUT.json] [--shared ../shared/data]
                              [--states 8] [--window 3]

--json OUT writes {"date", "commit", "columns", "peer", "folds": [{"train",
"test", "rows": {row: motion compare JSON}, "matched": {row: {...}}}],
"band": {column: [min, max]}}; docs/evaluation.md documents the fields.
"""
import argparse
import datetime
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
ap.add_argument("--shared", default=os.path.join(root, "..", "shared", "data"),
                help="the project's shared data (for the published peer's output)")
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
PEER_TAKE = "2_scott_0_2_2"
peer_bvh = os.path.join(args.shared, "paired", "beat2", "peers", f"mambatalk_{PEER_TAKE}.bvh")
peer_present = os.path.exists(peer_bvh)


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


# (JSON field, column title, format): the printed table; the JSON keeps every
# field of motion compare.
COLUMNS = [
    ("genea_hellinger_speed", "GH spd", "{:.3f}"),
    ("genea_hellinger_accel", "GH acc", "{:.3f}"),
    ("fid_k", "FID_k", "{:.1f}"),
    ("hellinger_speed", "kH spd", "{:.3f}"),
    ("hellinger_accel", "kH acc", "{:.3f}"),
    ("fd_kinetic", "kFD", "{:.1f}"),
    ("jerk_mean_m_s3", "jerk", "{:.0f}"),
    ("knee_jerk_mean_m_s3", "knee j", "{:.0f}"),
    ("hand_speed_mean_m_s", "v mean", "{:.2f}"),
    ("hands_moving_fraction", "moving", "{:.2f}"),
    ("hands_raised_fraction", "raised", "{:.2f}"),
    ("l1_div", "L1div", "{:.2f}"),
    ("beat_consistency", "BC", "{:.3f}"),
    ("beat_consistency_chance", "BC rnd", "{:.3f}"),
    ("accent_sync_fraction", "sync", "{:.2f}"),
    ("accent_sync_chance", "sync rnd", "{:.2f}"),
    ("ankle_lift_share", "ankle%", "{:.1%}"),
    ("near_copy_share_over_2s", "ncopy%", "{:.0%}"),
    ("longest_near_copy_s", "ncopy s", "{:.1f}"),
    ("library_repeat_share", "repeat%", "{:.0%}"),
    ("longest_copy_s", "copy s", "{:.1f}"),
    ("foot_slide_p95_m_s", "slide95", "{:.3f}"),
    ("max_joint_speed_m_s", "vmax", "{:.2f}"),
]
# Measures a reference row has of its own (the rest are distances to it).
SELF_MEASURES = {"jerk_mean_m_s3", "knee_jerk_mean_m_s3", "hand_speed_mean_m_s", "hands_moving_fraction", "hands_raised_fraction", "l1_div",
                 "accent_sync_fraction", "accent_sync_chance", "ankle_lift_share", "foot_slide_p95_m_s",
                 "max_joint_speed_m_s"}
MATCHED = ["GC", "GC online", "GMG", "BodySpeech", "random"]


def fmt(v, f):
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    return f.format(v)


def commit():
    try:
        return subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True).stdout.strip()
    except OSError:
        return ""


def print_table(rows):
    print(f"{'row':<17}" + "".join(f"{c[1]:>9}" for c in COLUMNS))
    for name, r in rows.items():
        if r is None:
            print(f"{name:<17}" + "absent (no ../shared data)".rjust(9))
            continue
        print(f"{name:<17}" + "".join(f"{fmt(r.get(k), f):>9}" for k, _, f in COLUMNS))


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
    train_wav = os.path.join(args.data, train + ".wav")
    test_bvh = os.path.join(args.data, test + ".bvh")
    test_wav = os.path.join(args.data, test + ".wav")
    model = os.path.join(d, "crf.kmodel")
    run([kinemo, "crf", "train", "--corpus", corpus, "--states", args.states, "--window", args.window,
         "--out", model, "--seed", args.seed], log)
    outs = {}
    mismatched = {}  # the same method's motion for the train take's speech
    ctrl = os.path.join(d, "gc.kctrl")
    run([kinemo, "controller", "build", "--library", train_bvh, "--model", model, "--out", ctrl], log)
    for name, extra in (("GC", []), ("GC online", ["--policy", "online"]),
                        ("random", ["--policy", "random", "--seed", args.seed])):
        for speech, table, suffix in ((test_wav, outs, ""), (train_wav, mismatched, "_other_speech")):
            out = os.path.join(d, name.replace(" ", "_") + suffix + ".bvh")
            run([kinemo, "controller", "synthesize", "--controller", ctrl, "--speech", speech, "--out", out] + extra,
                log)
            table[name] = (out, [train_bvh])
    for alg, name in (("gmg", "GMG"), ("bodyspeech", "BodySpeech")):
        for speech, table, suffix in ((test_wav, outs, ""), (train_wav, mismatched, "_other_speech")):
            out = os.path.join(d, name + suffix + ".bvh")
            run([kinemo, "gestures", speech, "--library", train_bvh, "--algorithm", alg, "--no-recognize", "-o", out],
                log)
            table[name] = (out, [train_bvh])
    outs["other take"] = (train_bvh, [train_bvh])
    if test == PEER_TAKE:
        outs["MambaTalk (peer)"] = (peer_bvh, [train_bvh]) if peer_present else None
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

    def judge(bvh, library):
        cmd = [kinemo, "motion", "compare", bvh, "--reference", test_bvh, "--audio", test_wav, "--json"]
        for lib in library:
            cmd += ["--library", lib]
        return json.loads(run(cmd, log))

    # The reference row: the real motion judged against itself, with the
    # train take as the library (its near copies: the natural level).
    reference = judge(test_bvh, [train_bvh])
    rows = {"reference (real)": reference}
    for name, o in outs.items():
        rows[name] = judge(*o) if o is not None else None
    matched = {"real speaker": {
        "r_motion": 1.0, "r_motion_mismatched": rows["other take"]["envelope_correlation"],
        "r_speech": reference["speech_envelope_correlation"],
        "r_speech_mismatched": rows["other take"]["speech_envelope_correlation"],
        "bc": reference["beat_consistency"], "bc_mismatched": rows["other take"]["beat_consistency"]}}
    for name in MATCHED:
        mm = judge(*mismatched[name])
        matched[name] = {
            "r_motion": rows[name]["envelope_correlation"], "r_motion_mismatched": mm["envelope_correlation"],
            "r_speech": rows[name]["speech_envelope_correlation"],
            "r_speech_mismatched": mm["speech_envelope_correlation"],
            "bc": rows[name]["beat_consistency"], "bc_mismatched": mm["beat_consistency"]}
    folds.append({"train": train, "test": test, "rows": rows, "matched": matched})

    print(f"\nfold: train {train}, animate {test}'s speech, judged against {test}'s real motion")
    shown = dict(rows)
    shown["reference (real)"] = {k: (v if k in SELF_MEASURES or k.startswith("near") or "copy" in k else None)
                                 for k, v in reference.items()}
    for k in ("beat_consistency", "beat_consistency_chance"):
        shown["reference (real)"][k] = reference[k]
    print_table(shown)
    print(f"\nmatched / mismatched ({test}'s real motion and speech; mismatched: motion for {train}'s speech)")
    print(f"{'row':<17}{'r motion':>10}{'mism.':>8}{'r speech':>10}{'mism.':>8}{'BC':>8}{'mism.':>8}")
    for name, m in matched.items():
        print(f"{name:<17}{m['r_motion']:>10.3f}{m['r_motion_mismatched']:>8.3f}{m['r_speech']:>10.3f}"
              f"{m['r_speech_mismatched']:>8.3f}{m['bc']:>8.3f}{m['bc_mismatched']:>8.3f}")

# Each measure's natural band: the speaker's other take against the reference.
band = {}
for k, _, _ in COLUMNS:
    vals = [f["rows"]["other take"].get(k) for f in folds]
    vals = [v for v in vals if isinstance(v, (int, float))]
    band[k] = [min(vals), max(vals)] if vals else None
print("\nnatural band (the speaker's other take against the reference, both folds)")
print(f"{'':<17}" + "".join(f"{c[1]:>9}" for c in COLUMNS))
for i, label in ((0, "band min"), (1, "band max")):
    print(f"{label:<17}" + "".join(f"{fmt(band[k][i] if band[k] else None, f):>9}" for k, _, f in COLUMNS))
print("(near copies of the other take: it is the library, 100 % by definition)")
if not peer_present:
    print(f"MambaTalk (peer): absent ({peer_bvh} not found)")
if args.json:
    with open(args.json, "w") as f:
        json.dump({"date": datetime.date.today().isoformat(), "commit": commit(),
                   "columns": [c[0] for c in COLUMNS],
                   "peer": {"row": "MambaTalk (peer)", "fold_test": PEER_TAKE, "path": peer_bvh,
                            "present": peer_present},
                   "folds": folds, "band": band}, f, indent=1)
    print(f"wrote {args.json}")

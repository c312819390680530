#!/usr/bin/env python3
"""Keyword-spotting threshold sweep on real speech with a transcription.

For each LibriVox clip (tests/data/speech, or ../shared/data/speech/librivox
when present) the keyword list is every transcript word of at least MIN_LEN
letters over ALL clips, so each clip is searched for words it contains and for
words it does not. A detection is a true positive when the word is in that
clip's transcript. Prints, per Sphinx -kws_threshold, precision and recall:
  bench/tools/keyword_eval.py [BUILD_DIR] [--min-len 6]
"""
import argparse
import json
import os
import re
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.dirname(os.path.dirname(here))

ap = argparse.ArgumentParser()
ap.add_argument("build", nargs="?", default=os.path.join(root, "build"))
ap.add_argument("--min-len", type=int, default=6)
ap.add_argument("--thresholds", default="1e-40,1e-30,1e-25,1e-20,1e-15,1e-10,1e-5")
args = ap.parse_args()

kinemo = os.path.join(args.build, "services", "cli", "kinemo")
shared = os.path.join(root, "..", "shared", "data", "speech", "librivox")
data = shared if os.path.isdir(shared) else os.path.join(root, "tests", "data", "speech")
transcripts = {}
with open(os.path.join(data, "transcription")) as f:
    for line in f:
        m = re.match(r"<s> (.*) </s> \((.*)\)", line.strip())
        if m and os.path.exists(os.path.join(data, m.group(2) + ".wav")):
            transcripts[m.group(2)] = set(m.group(1).split())
keywords = sorted({w for ws in transcripts.values() for w in ws if len(w) >= args.min_len})
print(f"data: {data}; {len(transcripts)} clips; {len(keywords)} keywords (>= {args.min_len} letters)")
print(f"{'threshold':>10} {'detections':>10} {'true':>5} {'false':>5} {'precision':>9} {'recall':>7}")
present = sum(len([w for w in keywords if w in ws]) for ws in transcripts.values())
for th in args.thresholds.split(","):
    tp = fp = 0
    found_true = 0
    for clip, words in transcripts.items():
        out = subprocess.run([kinemo, "prosody", os.path.join(data, clip + ".wav"), "--json",
                              "--keywords", ",".join(keywords), "--keyword-threshold", th],
                             capture_output=True, text=True)
        if out.returncode != 0:
            sys.exit(f"kinemo prosody failed: {out.stderr.strip()}")
        spotted = [w["word"] for w in json.loads(out.stdout).get("words", [])]
        tp += sum(1 for w in spotted if w in words)
        fp += sum(1 for w in spotted if w not in words)
        found_true += len({w for w in spotted if w in words})
    n = tp + fp
    print(f"{th:>10} {n:>10} {tp:>5} {fp:>5} {tp / n if n else float('nan'):>9.2f} {found_true / present:>7.2f}")
